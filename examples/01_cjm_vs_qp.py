"""CJM vs QP on one step: the paper's robot with a trocar on its constrained link.

The sda10f (torso + 7-axis arm, the paper's experiment) gets a hole 8 cm along link 6
(``arm_link_5_r``). One desired end-effector twist goes to the Constrained Jacobian
Matrix and to a QP (daqp) that holds the same two equalities. Both give the same joint
velocities; the link moves along its axis at the hole, never across it.

Run:  python examples/01_cjm_vs_qp.py
"""

import numpy as np
import pinocchio as pin

from constraints import Hole
from controllers import CJMController, QPController
from teleop import load_robot

np.set_printoptions(precision=5, suppress=True, linewidth=100)

robot = load_robot("sda10f")
q = robot.q_home.copy()
hole = Hole.on_link(robot, q, distance=0.08)  # a trocar where the link axis is now
twist = np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02])  # EE body twist [v; w]

cjm = CJMController(robot, [hole])
qp = QPController(robot, [hole], solver="daqp")
qd_cjm = cjm.solve(q, twist)
qd_qp = qp.solve(q, twist)

print(f"robot {robot.name}: {robot.model.nv} DoF, hole on {hole.link} at {hole.center.round(4)}")
print(f"twist       {twist}")
print(f"qd CJM      {qd_cjm}   ({cjm.info.method})")
print(f"qd QP       {qd_qp}   ({qp.info.method})")
print(f"max |qd_cjm - qd_qp| = {np.max(np.abs(qd_cjm - qd_qp)):.3e} rad/s")


def lateral_velocity(qd):
    """Speed (m/s) of the link point at the hole across the link axis (Pinocchio only)."""
    model, data = robot.model, robot.model.createData()
    frame = model.getFrameId(hole.link)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    axis = hole.link_axis
    p = (axis @ data.oMf[frame].actInv(hole.center)) * axis  # point of the axis at the hole
    J = pin.getFrameJacobian(model, data, frame, pin.LOCAL)
    velocity = J[:3] @ qd + np.cross(J[3:] @ qd, p)  # link coordinates
    return float(np.linalg.norm(velocity - (axis @ velocity) * axis))


J_ee = pin.computeFrameJacobian(robot.model, robot.model.createData(), q,
                                robot.model.getFrameId(robot.ee_frame), pin.LOCAL)
for name, qd in (("CJM", qd_cjm), ("QP", qd_qp)):
    print(f"{name:3s}: lateral velocity at the hole = {lateral_velocity(qd):.3e} m/s, "
          f"EE twist error = {np.linalg.norm(J_ee @ qd - twist):.3e}")
