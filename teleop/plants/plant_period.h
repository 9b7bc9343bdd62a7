// One control period of the MuJoCo plant: what it reads and writes (docs/design.md section
// 17.5), shared by plant_period.c (the period, against MuJoCo) and period_call.c (its call
// from Python, which knows MuJoCo's model and data only by address).
#ifndef CJM_PLANT_PERIOD_H
#define CJM_PLANT_PERIOD_H

struct mjModel_;
struct mjData_;

typedef struct PlantPeriod PlantPeriod;

// teleop/plants/compiled_period.py's PeriodBlock, field for field
struct PlantPeriod {
  const struct mjModel_* model;
  struct mjData_* data;
  double* command;            // nv: the joint velocity command (MuJoCo's dofs), copied in
  double* q;                  // nq: the loop's configuration the period starts from, copied in
                              // (identity only)
  const int* actuator_dofs;   // nu: each actuator's degree of freedom
  const double* effort_limit; // nv: each dof's effort limit (inf: none)
  double* ports;              // port_count blocks of port_wall.c's kPortSize doubles
  double* moved;              // nv, out: the velocity that takes q to the simulated qpos
  double* reached;            // nq, out: q + moved dt, where moved takes q over the period
                              // (both identity only)
  double* summary;            // out: torque ratio, contact count, deepest penetration
  void (*run)(const PlantPeriod* period); // cjm_plant_period (period_call.c calls it)
  double dt;
  int nstep;
  int port_count;
  int nv;
  int nq;
  int identity;  // the loop's coordinates are MuJoCo's: moved and reached are computed here
};

#endif
