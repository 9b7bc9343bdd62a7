"""The closed-loop collision fuzz: random crossing targets on ``sda10f_dual``, a trocar on
each arm, every self-collision pair kept apart (docs/design.md section 18.7).

Each run starts at a random configuration near home where the two arms are within the
detection distance of each other (none closer than 1 cm), places a hole on each
constrained link there, draws a target point for each tip (5 to 20 cm towards and past
the other tip, 5 cm of noise each way), and steers both tips to it for ``steps`` periods
of 1 ms: ``q`` integrated from the command (``pin.integrate``), the tips' linear velocities
from a proportional law saturated at 0.15 m/s (the task is the tips' positions: an
instrument through a trocar cannot hold its orientation while it moves sideways). After
every step it measures, with its own collision avoidance, the smallest distance of every
pair within the detection distance (coal's, exact), and the holes' errors; it checks each
command against the joint box.

``python -m tests.collision_fuzz --runs 2000`` prints the figures per controller.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from constraints import Hole
from constraints.collision import CollisionAvoidance
from teleop import load_robot
from teleop.controller_specs import make_controller

ROBOT = "sda10f_dual"
HOLE_DISTANCE = 0.08
PERIOD = 1e-3
GAIN = 5.0
MAX_SPEED = 0.15
#: the task: the tips' linear velocities (their rotations left free)
TWIST_WEIGHT = [1.0, 1.0, 1.0, 0.0, 0.0, 0.0] * 2


@dataclass
class FuzzResult:
    """What one controller did over the runs."""

    controller: str
    runs: int = 0
    steps: int = 0
    minimum_distance: float = float("inf")
    worst_run: int = -1
    penetrations: int = 0          # steps with a pair at a negative distance
    below_safety: int = 0          # steps with a pair closer than d_s - 0.5 mm
    hole_error_max: float = 0.0    # m
    box_violations: int = 0        # commands outside the joint box (beyond its test's slack)
    non_finite: int = 0
    statuses: dict[str, int] = field(default_factory=dict)
    failures: dict[str, int] = field(default_factory=dict)  # failed steps by their message
    seconds: float = 0.0


def close_start(robot, avoidance: CollisionAvoidance, rng: np.random.Generator) -> np.ndarray:
    """A configuration near home (normal offsets of 0.4 rad, kept 0.1 rad inside the joint
    limits) with a pair of the two arms within the detection distance and every pair at
    least 1 cm apart."""
    model, data = robot.model, robot.model.createData()
    lower, upper = model.lowerPositionLimit + 0.1, model.upperPositionLimit - 0.1
    while True:
        q = np.clip(pin.integrate(model, robot.q_home, rng.normal(scale=0.4, size=model.nv)),
                    lower, upper)
        pin.computeJointJacobians(model, data, q)
        rows = avoidance.rows(model, data)
        if rows.minimum_distance > 0.01 and any("left" in pair and "right" in pair
                                                for pair in rows.pairs):
            return q


def random_targets(robot, q: np.ndarray, rng: np.random.Generator) -> list[np.ndarray]:
    """A target point per tip: 5 to 20 cm towards and past the other tip, 5 cm of noise."""
    model, data = robot.model, robot.model.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    tips = [data.oMf[frame].translation.copy() for frame in robot.ee_frame_ids]
    targets = []
    for tip, other in zip(tips, tips[::-1]):
        towards = (other - tip) / max(np.linalg.norm(other - tip), 1e-9)
        targets.append(tip + towards * rng.uniform(0.05, 0.20) + rng.uniform(-0.05, 0.05, 3))
    return targets


def steering_twist(robot, data: pin.Data, targets: list[np.ndarray]) -> np.ndarray:
    """The stacked LOCAL twists whose linear parts steer the tips to ``targets`` (a
    proportional law, saturated); the angular parts are zero and weigh nothing."""
    twists = []
    for frame, target in zip(robot.ee_frame_ids, targets):
        tip = data.oMf[frame]
        velocity = GAIN * (target - tip.translation)
        speed = np.linalg.norm(velocity)
        if speed > MAX_SPEED:
            velocity *= MAX_SPEED / speed
        twists.append(np.concatenate([tip.rotation.T @ velocity, np.zeros(3)]))
    return np.concatenate(twists)


def fuzz(controller_spec: str, runs: int, steps: int = 400, seed: int = 0) -> FuzzResult:
    """``runs`` closed-loop runs of ``controller_spec`` with collision avoidance."""
    robot = load_robot(ROBOT)
    model = robot.model
    avoidance = CollisionAvoidance(robot)
    measure = CollisionAvoidance(robot)
    safety = measure.safety_distance - 0.5e-3
    # on its iteration caps alone, as compare's controllers: a CPU deadline would make the
    # counts depend on the machine's load (docs/design.md 10.6)
    controller = make_controller(controller_spec, robot, (), dt=PERIOD,
                                 twist_weight=TWIST_WEIGHT, time_budget=None)
    controller.set_collisions(avoidance)
    result = FuzzResult(controller_spec)
    limit = controller.velocity_limit
    slack = 1e-9 * np.where(np.isfinite(limit), limit, 1.0)  # the box test's (BoxTest)
    data = model.createData()
    start = time.perf_counter()
    for run in range(runs):
        rng = np.random.default_rng([seed, run])
        q = close_start(robot, measure, rng)
        holes = [Hole.on_link(robot, q, distance=HOLE_DISTANCE, link=link)
                 for link in robot.constrained_links]
        controller.set_constraints(holes)
        targets = random_targets(robot, q, rng)
        controller.reset()
        for _ in range(steps):
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            lower, upper = controller.bounds(q)
            lower, upper = lower - slack, upper + slack
            qd = controller.solve(q, steering_twist(robot, data, targets))
            status = controller.info.status.value
            result.statuses[status] = result.statuses.get(status, 0) + 1
            if status == "failed":
                reason = controller.info.message[:80]
                result.failures[reason] = result.failures.get(reason, 0) + 1
            if not np.all(np.isfinite(qd)):
                result.non_finite += 1
                break
            if np.any(qd < lower) or np.any(qd > upper):
                result.box_violations += 1
            q = pin.integrate(model, q, qd * PERIOD)
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            distance = measure.rows(model, data).minimum_distance
            if distance < result.minimum_distance:
                result.minimum_distance, result.worst_run = distance, run
            result.penetrations += distance < 0.0
            result.below_safety += distance < safety
            for hole in holes:
                error = hole.violation(data.oMf[model.getFrameId(hole.link)])
                result.hole_error_max = max(result.hole_error_max, error)
            result.steps += 1
        result.runs += 1
    result.seconds = time.perf_counter() - start
    return result


def format_results(results: list[FuzzResult]) -> str:
    lines = [f"{'controller':<14}{'runs':>6}{'steps':>9}{'min dist mm':>13}{'< 0':>6}"
             f"{'< ds-0.5mm':>11}{'hole um':>9}{'box':>5}{'s':>8}  statuses"]
    for r in results:
        statuses = ", ".join(f"{name} {count}" for name, count in sorted(r.statuses.items()))
        lines.append(f"{r.controller:<14}{r.runs:>6}{r.steps:>9}{1e3 * r.minimum_distance:>13.3f}"
                     f"{r.penetrations:>6}{r.below_safety:>11}{1e6 * r.hole_error_max:>9.3f}"
                     f"{r.box_violations:>5}{r.seconds:>8.1f}  {statuses}")
        lines += [f"    failed {count}: {reason}" for reason, count in
                  sorted(r.failures.items(), key=lambda item: -item[1])[:3]]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=2000)
    parser.add_argument("--steps", type=int, default=400)
    parser.add_argument("--controllers", default="cjm,qp:daqp,qp:proxqp,mink:daqp")
    parser.add_argument("--seed", type=int, default=0)
    arguments = parser.parse_args()
    results = []
    for spec in arguments.controllers.split(","):
        results.append(fuzz(spec.strip(), arguments.runs, arguments.steps, arguments.seed))
        print(format_results(results[-1:]), flush=True)
    print(format_results(results))


if __name__ == "__main__":
    main()
