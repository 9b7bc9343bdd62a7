"""Two instruments through two trocars on one torso: the dual-arm SDA10F, both tools driven.

Each arm's link 6 passes through a hole 8 cm along it. Both tool tips move on their own
circles for 2 s; the CJM (general form over the stacked rows and tasks, docs/design.md
section 11) and the QP (daqp) run side by side from the same start. 15 joints minus 4 hole
directions leave 11 for 12 task entries: both full twists cannot be met. The operator
commands the tips, so ``twist_weight`` asks for the tips' linear velocities only (weight 0
on the angular ones); the orientations do what the trocars allow, and the posture the rest.

Run:  python examples/07_two_trocars.py
"""

import numpy as np
import pinocchio as pin

from constraints import Hole
from controllers import CJMController, QPController
from teleop import load_robot

robot = load_robot("sda10f_dual")
model, data = robot.model, robot.model.createData()
q0 = robot.q_home.copy()
holes = [Hole.on_link(robot, q0, distance=0.08, link=link) for link in robot.constrained_links]
tips_only = [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]  # per EE: [v; w]
controllers = {"CJM": CJMController(robot, holes, twist_weight=tips_only),
               "QP": QPController(robot, holes, solver="daqp", twist_weight=tips_only)}
dt, radius, gain = 1e-3, 0.02, 20.0


def tool_positions(q: np.ndarray) -> np.ndarray:
    pin.framesForwardKinematics(model, data, q)
    return np.array([data.oMf[frame].translation.copy() for frame in robot.ee_frame_ids])


start = tool_positions(q0)
print(f"robot {robot.name}: {model.nv} DoF, EEs {list(robot.ee_frames)}")
for name, controller in controllers.items():
    q, worst_hole, worst_tip, statuses = q0.copy(), 0.0, 0.0, {}
    for k in range(2000):
        t = k * dt
        # the left tip circles in the x-z plane at 0.5 Hz, the right one in y-z at 0.3 Hz
        goals = start + radius * np.array([
            [np.sin(np.pi * t), 0.0, 1.0 - np.cos(np.pi * t)],
            [0.0, np.sin(0.6 * np.pi * t), 1.0 - np.cos(0.6 * np.pi * t)]])
        goal_velocities = radius * np.array([  # fed forward
            [np.pi * np.cos(np.pi * t), 0.0, np.pi * np.sin(np.pi * t)],
            [0.0, 0.6 * np.pi * np.cos(0.6 * np.pi * t), 0.6 * np.pi * np.sin(0.6 * np.pi * t)]])
        tips = tool_positions(q)
        twist = np.concatenate([  # each tip's world velocity in its EE frame; no rotation asked
            np.concatenate([data.oMf[frame].rotation.T @ (velocity + gain * (goal - tip)),
                            np.zeros(3)])
            for frame, goal, velocity, tip in zip(robot.ee_frame_ids, goals, goal_velocities, tips)])
        qd = controller.solve(q, twist)
        statuses[controller.info.status.value] = statuses.get(controller.info.status.value, 0) + 1
        q = pin.integrate(model, q, qd * dt)
        pin.framesForwardKinematics(model, data, q)
        worst_hole = max(worst_hole, max(
            float(np.linalg.norm(hole.error(data.oMf[model.getFrameId(hole.link)])))
            for hole in holes))
        worst_tip = max(worst_tip, float(np.max(np.linalg.norm(tool_positions(q) - goals, axis=1))))
    controllers[name] = q
    print(f"{name:3s}: max hole error = {worst_hole:.2e} m, max tip error = {worst_tip:.2e} m, "
          f"steps {statuses}")
print(f"max |q_cjm - q_qp| after 2 s = {np.max(np.abs(controllers['CJM'] - controllers['QP'])):.2e} rad")
