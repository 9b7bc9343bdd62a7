"""Two instruments pushed into each other: collision avoidance keeps the arms 5 mm apart
while both trocars hold (docs/design.md section 18)."""

import numpy as np
import pinocchio as pin

from constraints import Hole
from constraints.collision import CollisionAvoidance
from controllers import CJMController
from teleop import load_robot

robot = load_robot("sda10f_dual")
model, dt = robot.model, 1e-3
collisions = CollisionAvoidance(robot)  # every self-collision pair: d_s 5 mm, d_i 5 cm
print(f"{len(collisions.pairs)} pairs checked, e.g. {collisions.pairs[0]}")


def tips_together(q: np.ndarray, speed: float) -> np.ndarray:
    """Both tips' body twists: towards each other along the world y axis at ``speed``."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    twist = []
    for frame, sign in zip(robot.ee_frame_ids, (-1.0, 1.0)):
        twist += [*(data.oMf[frame].rotation.T @ [0.0, sign * speed, 0.0]), 0.0, 0.0, 0.0]
    return np.array(twist)


# 1. the tips brought together, no trocar yet (the tips' positions are the task)
free = CJMController(robot, collisions=collisions, twist_weight=[1, 1, 1, 0, 0, 0] * 2)
q = robot.q_home.copy()
for _ in range(5000):  # about 2.2 s at 0.1 m/s
    q = pin.integrate(model, q, dt * free.solve(q, tips_together(q, 0.1)))
    if free.info.minimum_distance <= 0.01:
        break
print(f"arms {1e3 * free.info.minimum_distance:.1f} mm apart ({free.info.closest_pair})")

# 2. a trocar on each arm where it is now; push on for a second
holes = [Hole.on_link(robot, q, distance=0.08, link=link) for link in robot.constrained_links]
controller = CJMController(robot, holes, collisions=collisions)
for _ in range(1000):
    q = pin.integrate(model, q, dt * controller.solve(q, tips_together(q, 0.02)))
distance, pair = collisions.minimum_distance(q)
data = model.createData()
pin.framesForwardKinematics(model, data, q)
trocar = max(hole.violation(data.oMf[model.getFrameId(hole.link)]) for hole in holes)
print(f"after 1 s of pushing: {1e3 * distance:.3f} mm between {pair}, "
      f"trocar error {1e6 * trocar:.2f} um")
print(f"status {controller.info.status.value}: {controller.info.message}")
