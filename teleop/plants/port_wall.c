// The abdominal wall at each port, compiled: MuJoCo's passive-force callback (mjcb_passive)
// applying teleop/plants/walls.py's PortWall inside mj_step (docs/design.md section 17.5).
//
// The plant attaches an MjData and its ports (cjm_wall_attach) for one mj_step call and
// detaches it after, in the thread that steps it: MuJoCo calls the callback in the thread
// that called mj_step (no thread pool is bound to a plant's MjData), so the attachment is
// that thread's own (thread-local: no table, no lock) and the callback, installed once
// for the process, does nothing for any other MjData. Per port, at the kinematics of the
// physics step (the callback runs in mj_fwdVelocity, where mj_step1 ends), with o, R the
// link site's position and rotation:
//
//     a = R a_link,  P = o + ((c - o) . a) a,  v = J_P qd,
//     F = -k (P - c) - c_d ((v - v_c) - ((v - v_c) . a) a),  qfrc_passive += J_P^T F,
//
// the math of PortWall.port and PortWall.force, and the force, its spring part and |P - c|
// written back for the plant's measures (the period's last physics step's stay).
#include <mujoco/mujoco.h>
#include <math.h>
#include <stddef.h>

// one port's block of doubles, the layout of teleop/plants/compiled_wall.py's PORT_FIELDS
enum {
  kBody, kSite, kAxis, kCenter = kAxis + 3, kVelocity = kCenter + 3, kStiffness = kVelocity + 3,
  kDamping, kForce, kSpring = kForce + 3, kDisplacement = kSpring + 3, kPortSize
};

typedef struct {
  const mjData* data;
  double* ports;
  int count;
} Attached;

// the MjData this thread is stepping with ports, and its ports (data NULL: none)
static _Thread_local Attached attached;

//! Apply ``count`` ports (``ports``: count blocks of kPortSize doubles) to ``data``'s
//! physics steps in this thread until cjm_wall_detach.
void cjm_wall_attach(const mjData* data, double* ports, int count) {
  attached.data = data;
  attached.ports = ports;
  attached.count = count;
}

//! Stop applying ports to ``data``.
void cjm_wall_detach(const mjData* data) {
  if (attached.data == data) attached.data = NULL;
}

static void apply_port(const mjModel* m, mjData* d, double* port, mjtNum* jacobian) {
  const int body = (int)port[kBody], site = (int)port[kSite];
  const mjtNum* origin = d->site_xpos + 3 * site;
  const mjtNum* rotation = d->site_xmat + 9 * site;
  const double* link_axis = port + kAxis;
  const double* center = port + kCenter;
  double axis[3], point[3], velocity[3], relative[3];
  for (int i = 0; i < 3; ++i)
    axis[i] = rotation[3 * i] * link_axis[0] + rotation[3 * i + 1] * link_axis[1] +
              rotation[3 * i + 2] * link_axis[2];
  const double along = axis[0] * (center[0] - origin[0]) + axis[1] * (center[1] - origin[1]) +
                       axis[2] * (center[2] - origin[2]);
  for (int i = 0; i < 3; ++i) point[i] = origin[i] + along * axis[i];
  mj_jac(m, d, jacobian, NULL, point, body);
  for (int i = 0; i < 3; ++i) {
    velocity[i] = 0.0;
    for (int j = 0; j < m->nv; ++j) velocity[i] += jacobian[i * m->nv + j] * d->qvel[j];
    relative[i] = velocity[i] - port[kVelocity + i];
  }
  const double axial = axis[0] * relative[0] + axis[1] * relative[1] + axis[2] * relative[2];
  double* force = port + kForce;
  double* spring = port + kSpring;
  double displacement2 = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double offset = point[i] - center[i];
    spring[i] = -port[kStiffness] * offset;
    force[i] = spring[i] - port[kDamping] * (relative[i] - axial * axis[i]);
    displacement2 += offset * offset;
  }
  port[kDisplacement] = sqrt(displacement2);
  for (int j = 0; j < m->nv; ++j)
    d->qfrc_passive[j] += jacobian[j] * force[0] + jacobian[m->nv + j] * force[1] +
                          jacobian[2 * m->nv + j] * force[2];
}

//! The callback (mjfGeneric): the ports attached to ``d`` in this thread, if any.
void cjm_wall_passive(const mjModel* m, mjData* d) {
  if (attached.data != d) return;
  mj_markStack(d);
  mjtNum* jacobian = mj_stackAllocNum(d, 3 * m->nv);
  for (int k = 0; k < attached.count; ++k)
    apply_port(m, d, attached.ports + k * kPortSize, jacobian);
  mj_freeStack(d);
}
