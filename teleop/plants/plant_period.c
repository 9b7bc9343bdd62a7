// One control period of the MuJoCo plant in one call (docs/design.md section 17.5): what
// teleop/plants/mujoco_plant.py's MujocoPlant.advance does around mj_step on a perfect
// interface, the command given in MuJoCo's dofs; the last two lines only for a robot whose
// Pinocchio and MuJoCo coordinates are the same (JointMap.identity: 1-dof joints in the
// same order, q and v alike; otherwise the caller maps qpos to its own coordinates):
//
//     ctrl[a] = v_cmd[dof(a)]                      (each dof's reference and feed-forward)
//     mj_step(m, d) nstep times, the ports' walls attached (port_wall.c)
//     ratio = max_j |qfrc_actuator_j| / effort_j    (NaN when one of them is NaN)
//     moved = (qpos - q) / dt                       (pin.difference of 1-dof joints, / dt)
//     reached = q + moved dt                        (pin.integrate(q, moved dt) of them)
//
// with the contacts' count and the deepest penetration max(0, -min(0, dist)) for the
// period's measures. Each line is the Python path's arithmetic in the same order, so the
// two give the same bits (built with -ffp-contract=off: no fused multiply-add).
#include <mujoco/mujoco.h>
#include <math.h>

#include "plant_period.h"

void cjm_wall_attach(const mjData* data, double* ports, int count);
void cjm_wall_detach(const mjData* data);

enum { kRatio, kContacts, kPenetration };

//! Run ``period``.
void cjm_plant_period(const PlantPeriod* period) {
  const mjModel* m = period->model;
  mjData* d = period->data;
  for (int a = 0; a < m->nu; ++a) d->ctrl[a] = period->command[period->actuator_dofs[a]];
  if (period->port_count > 0) cjm_wall_attach(d, period->ports, period->port_count);
  for (int step = 0; step < period->nstep; ++step) mj_step(m, d);
  if (period->port_count > 0) cjm_wall_detach(d);
  double ratio = 0.0;
  int finite = 1;
  for (int j = 0; j < m->nv; ++j) {
    const double share = fabs(d->qfrc_actuator[j]) / period->effort_limit[j];
    if (isnan(share)) finite = 0;
    if (j == 0 || share > ratio) ratio = share;
  }
  period->summary[kRatio] = finite ? ratio : NAN;
  double deepest = 0.0;
  for (int c = 0; c < d->ncon; ++c) {
    const double dist = d->contact[c].dist;
    if (isnan(dist) || isnan(deepest)) deepest = NAN;
    else if (dist < deepest) deepest = dist;
  }
  const double penetration = -deepest;
  period->summary[kContacts] = d->ncon;
  period->summary[kPenetration] = penetration > 0.0 ? penetration : 0.0;
  if (!period->identity) return;  // the caller maps qpos to its coordinates
  for (int i = 0; i < m->nq; ++i) {
    period->moved[i] = (d->qpos[i] - period->q[i]) / period->dt;
    const double step = period->moved[i] * period->dt;
    period->reached[i] = period->q[i] + step;
  }
}
