"""A barrier: the operator pushes the tool into a floor; the tool point stops on it.

The sda10f keeps its trocar on link 6, and a barrier (one inequality, a velocity damper
``n . v >= -K d``) lies 1 cm below the tool point. The operator's target goes 3 cm down,
2 cm through the floor. The closed loop tracks it with the CJM and with a QP; the tool
point approaches the floor exponentially and never crosses it (signed distance >= 0).

Run:  python examples/03_barrier.py
"""

import numpy as np
import pinocchio as pin

from constraints import Barrier, Hole
from controllers import CJMController, QPController
from teleop import load_robot
from teleop.loop import LoopConfig, TeleopLoop

robot = load_robot("sda10f")
q0 = robot.q_home.copy()
model, data = robot.model, robot.model.createData()
tool = model.getFrameId(robot.ee_frame)
pin.framesForwardKinematics(model, data, q0)
start = data.oMf[tool].copy()
normal = np.array([0.0, 0.0, 1.0])  # allowed side: above the floor
floor = start.translation - 0.01 * normal
config = LoopConfig(rate=1000.0)


def make_constraints():
    hole = Hole.on_link(robot, q0, distance=0.08)
    barrier = Barrier.through_link_point(robot, q0, normal=normal, link=robot.ee_frame,
                                         link_point=np.zeros(3), plane_point=floor)
    return [hole, barrier]


def target(t):
    """3 cm down over 2 s (smoothstep), then hold: 2 cm behind the floor."""
    s = min(t / 2.0, 1.0)
    return pin.SE3(start.rotation, start.translation - 0.03 * (3 * s**2 - 2 * s**3) * normal)


print(f"tool starts {100 * normal @ (start.translation - floor):.1f} cm above the barrier; "
      f"the target ends {100 * normal @ (target(3.0).translation - floor):.1f} cm (behind it)")
for name, controller in (("CJM", CJMController(robot, make_constraints(), dt=config.dt)),
                         ("QP daqp", QPController(robot, make_constraints(), solver="daqp",
                                                  dt=config.dt))):
    loop = TeleopLoop(robot, controller, q0=q0, config=config)
    distances, hole_errors, failed = [], [], 0
    for i in range(3000):  # 3 s
        record = loop.tick(target((i + 1) * config.dt))
        pin.framesForwardKinematics(model, data, loop.q)
        distances.append(normal @ (data.oMf[tool].translation - floor))  # Pinocchio, not the controller
        hole_errors.append(record.constraint_error)
        failed += record.failed
    distances = np.array(distances)
    print(f"{name:8s} min signed distance = {distances.min():+.3e} m, "
          f"final = {distances[-1]:+.3e} m, hole error max = {max(hole_errors):.1e} m, "
          f"failed steps = {failed}")
