"""Any URDF: a trocar on the Panda's forearm, from example-robot-data.

``load_robot`` takes a URDF path plus what the controllers need: the EE frame, the
constrained link and that link's long axis (link coordinates). Without a ``q_home`` it
picks a home inside the joint limits (every joint at least 10 % of its range from each
bound) and away from singularities for a hole on that link (docs/design.md section 6.1).
Here the hole sits 15 cm
along the Panda's forearm (``panda_link4``, from joint 4 towards joint 5). Only 4 joints
lie before that link, so the CJM uses its general null-space form. The hole leaves the
hand 5 DoF, so a 6D twist is met in the least-squares sense: the default CJM treats the
missing direction like a singularity and damps (lambda 0.05); without damping
(``singular_threshold=0``) it is the exact least-squares optimum, as the QP's.

Needs example-robot-data (``pip install -e ".[test]"``).

Run:  python examples/04_any_urdf.py
"""

import importlib.metadata

import numpy as np
import pinocchio as pin

from constraints import Hole
from controllers import CJMController, QPController
from teleop import load_robot

np.set_printoptions(precision=5, suppress=True, linewidth=110)

# example-robot-data installs its robots under <site-packages>/cmeel.prefix/share
share = importlib.metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share")
urdf = share / "example-robot-data/robots/panda_description/urdf/panda.urdf"
forearm = np.array([-0.0825, 0.384, 0.0])  # joint 4 -> joint 5, in panda_link4 coordinates
robot = load_robot(urdf, ee_frame="panda_hand", constrained_link="panda_link4",
                   link_axis=forearm / np.linalg.norm(forearm), package_dirs=[str(share)])
print(f"loaded {urdf.name}: {robot.name}, nq={robot.model.nq}, nv={robot.model.nv}, "
      f"EE {robot.ee_frame}, constrained link {robot.constrained_link}")
lower, upper = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
margin = np.min(np.minimum(robot.q_home - lower, upper - robot.q_home) / (upper - lower))
print(f"home {robot.q_home}: every joint {100 * margin:.0f} % of its range or more from a bound")

q = robot.q_home.copy()
hole = Hole.on_link(robot, q, distance=0.15)
twist = np.array([0.02, -0.01, 0.01, 0.05, 0.02, -0.03])
cjm = CJMController(robot, [hole])
exact = CJMController(robot, [hole], singular_threshold=0.0)  # no damping
qp = QPController(robot, [hole], solver="daqp")
qd_cjm, qd_exact, qd_qp = cjm.solve(q, twist), exact.solve(q, twist), qp.solve(q, twist)
print(f"qd CJM        {qd_cjm}  ({cjm.info.method}, damping {cjm.info.damping:g})")
print(f"qd CJM exact  {qd_exact}  ({exact.info.method}, damping {exact.info.damping:g})")
print(f"qd QP         {qd_qp}  ({qp.info.method})")
print(f"max |qd_cjm - qd_qp|       = {np.max(np.abs(qd_cjm - qd_qp)):.3e} rad/s (damped)")
print(f"max |qd_cjm_exact - qd_qp| = {np.max(np.abs(qd_exact - qd_qp)):.3e} rad/s")

model, data = robot.model, robot.model.createData()
pin.computeJointJacobians(model, data, q)
pin.updateFramePlacements(model, data)
link = model.getFrameId(hole.link)
axis = hole.link_axis
p = (axis @ data.oMf[link].actInv(hole.center)) * axis  # the link point at the hole
J_link = pin.getFrameJacobian(model, data, link, pin.LOCAL)
J_ee = pin.getFrameJacobian(model, data, model.getFrameId(robot.ee_frame), pin.LOCAL)
for name, qd in (("CJM", qd_cjm), ("CJM exact", qd_exact), ("QP", qd_qp)):
    v = J_link[:3] @ qd + np.cross(J_link[3:] @ qd, p)
    lateral = np.linalg.norm(v - (axis @ v) * axis)
    print(f"{name:9s}: lateral velocity at the hole = {lateral:.3e} m/s, "
          f"EE twist error = {np.linalg.norm(J_ee @ qd - twist):.4e}")
