"""The outside peer: the same trocar problem through mink.

``MinkController`` hands the task to ``mink.solve_ik`` on a MuJoCo model compiled from
the same URDF, with the hole's two rows as a hard constraint. On the sda10f with the hole
on link 6 (example 01's problem) it should reach the CJM's joint velocities; this prints
how far apart they are, both constraint residuals and one-step times.

Run:  python examples/05_mink_peer.py
"""

import time

import numpy as np
import pinocchio as pin

from constraints import Hole
from controllers import CJMController, MinkController
from teleop import load_robot

np.set_printoptions(precision=5, suppress=True, linewidth=100)

robot = load_robot("sda10f")
q = robot.q_home.copy()
hole = Hole.on_link(robot, q, distance=0.08)
twist = np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02])

cjm = CJMController(robot, [hole])
mink = MinkController(robot, [hole], solver="daqp")  # builds the MuJoCo model once
qd_cjm = cjm.solve(q, twist)
qd_mink = mink.solve(q, twist)
print(f"qd CJM   {qd_cjm}  ({cjm.info.method})")
print(f"qd mink  {qd_mink}  ({mink.info.method})")
deviation = np.max(np.abs(qd_mink - qd_cjm))
print(f"deviation max |qd_mink - qd_cjm| = {deviation:.3e} rad/s "
      f"(relative {deviation / np.max(np.abs(qd_cjm)):.1e})")

model, data = robot.model, robot.model.createData()
pin.computeJointJacobians(model, data, q)
pin.updateFramePlacements(model, data)
link = model.getFrameId(hole.link)
p = (hole.link_axis @ data.oMf[link].actInv(hole.center)) * hole.link_axis
J_link = pin.getFrameJacobian(model, data, link, pin.LOCAL)
J_ee = pin.getFrameJacobian(model, data, model.getFrameId(robot.ee_frame), pin.LOCAL)
for name, controller, qd in (("CJM", cjm, qd_cjm), ("mink", mink, qd_mink)):
    v = J_link[:3] @ qd + np.cross(J_link[3:] @ qd, p)
    lateral = np.linalg.norm(v - (hole.link_axis @ v) * hole.link_axis)
    times = []
    for _ in range(50):
        start = time.perf_counter()
        controller.solve(q, twist)
        times.append(time.perf_counter() - start)
    print(f"{name:4s}: lateral velocity at the hole = {lateral:.3e} m/s, EE twist error = "
          f"{np.linalg.norm(J_ee @ qd - twist):.3e}, step median = {1e6 * np.median(times):.0f} us")
