"""One-step timing of every controller on the built-in robots (``teleop bench``)."""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from typing import Callable, Sequence

import numpy as np

from constraints import Hole

from .registry import make_controller
from .robot import load_robot

#: hole distance along the constrained link of each built-in robot (m)
DEFAULT_HOLE_DISTANCE = {"sda10f": 0.08, "ur5_instrument": 0.20}


@dataclass(frozen=True)
class StepTiming:
    """Timing of ``solve(q, twist)`` for one controller on one robot (microseconds)."""

    robot: str
    controller: str
    median_us: float
    p99_us: float
    max_us: float
    iterations: int
    max_constraint_residual: float  # m/s, max |A qd - b| over the timed steps


def time_steps(step: Callable[[np.ndarray], None], configurations: np.ndarray,
               warmup: int) -> np.ndarray:
    """Per-call wall time (us) of ``step(q)`` over ``configurations`` after a warm-up."""
    for q in configurations[:warmup]:
        step(q)
    times = np.empty(len(configurations))
    clock = time.perf_counter_ns
    for i, q in enumerate(configurations):
        start = clock()
        step(q)
        times[i] = (clock() - start) * 1e-3
    return times


def bench_controller(robot_name: str, spec: str, iterations: int = 2000,
                     warmup: int = 200, seed: int = 0) -> StepTiming:
    """Time one controller on a hole at the robot's home, over nearby configurations."""
    robot = load_robot(robot_name)
    q0 = robot.q_home.copy()
    hole = Hole.on_link(robot, q0, distance=DEFAULT_HOLE_DISTANCE.get(robot_name, 0.1))
    controller = make_controller(spec, robot, [hole])
    rng = np.random.default_rng(seed)
    configurations = q0 + rng.uniform(-0.02, 0.02, (iterations, robot.model.nq))
    twist = np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02])
    residual = 0.0

    def step(q: np.ndarray) -> None:
        nonlocal residual
        controller.solve(q, twist)
        residual = max(residual, controller.info.equality_residual)

    times = time_steps(step, configurations, warmup)
    return StepTiming(robot=robot_name, controller=spec, median_us=float(np.median(times)),
                      p99_us=float(np.percentile(times, 99)), max_us=float(times.max()),
                      iterations=iterations, max_constraint_residual=residual)


def run_bench(robots: Sequence[str] = ("sda10f", "ur5_instrument"),
              controllers: Sequence[str] = ("cjm", "cjm:general", "qp:proxqp", "qp:daqp", "qp:osqp"),
              iterations: int = 2000) -> list[StepTiming]:
    return [bench_controller(r, c, iterations=iterations, warmup=max(1, iterations // 10))
            for r in robots for c in controllers]


def format_table(results: Sequence[StepTiming]) -> str:
    lines = [f"{'robot':<16}{'controller':<14}{'median us':>11}{'p99 us':>10}{'max us':>10}"
             f"{'residual m/s':>14}"]
    for r in results:
        lines.append(f"{r.robot:<16}{r.controller:<14}{r.median_us:>11.1f}{r.p99_us:>10.1f}"
                     f"{r.max_us:>10.1f}{r.max_constraint_residual:>14.1e}")
    return "\n".join(lines)


def write_json(results: Sequence[StepTiming], path: str) -> None:
    with open(path, "w", encoding="utf-8") as handle:
        json.dump([asdict(r) for r in results], handle, indent=2)
