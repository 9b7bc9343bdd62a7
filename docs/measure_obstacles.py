"""How the collision avoidance's cost grows with the obstacles (docs/design.md 18.3, "How
many obstacles"): sda10f at home, spheres of 5 cm scattered at random over 4 m by 4 m by
2 m around it (the same field each run), the cap lifted for the measure. Per count:

* ``build``: making the avoidance (its geometry model and pairs), once per change of the
  obstacles;
* ``rows``: ``CollisionAvoidance.rows``, the Python rows the QP, mink and the Python CJM
  step use, median of 300 steps at home;
* ``compiled step``: the compiled CJM step with the avoidance (its own pairs loop in C++),
  median of 300 steps at home;
* ``near``: the obstacles the broadphase keeps (their boxes meet the robot's);
* ``memory``: what making the compiled controller added to the process (its resident
  size, Linux's ``/proc/self/statm``).

Run:  OPENBLAS_NUM_THREADS=1 python docs/measure_obstacles.py [--counts 100,400,1200]
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
import pinocchio as pin

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import constraints.collision.avoidance as avoidance_module  # noqa: E402
from constraints.collision import CollisionAvoidance, Sphere  # noqa: E402
from controllers import CJMController  # noqa: E402
from teleop import load_robot  # noqa: E402


def resident_mb() -> float:
    """The process's resident size (MB)."""
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def median_time(call, repeats: int = 300) -> float:
    """The median of ``repeats`` timings of ``call()`` (s)."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", default="100,400,1200")
    args = parser.parse_args()
    robot = load_robot("sda10f")
    q = robot.q_home
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    twist = np.array([0.05, 0.0, -0.05, 0.0, 0.0, 0.0])
    print("| obstacles | build (ms) | rows (ms) | compiled step (ms) | near | memory (MB) |")
    print("|---|---|---|---|---|---|")
    for count in (int(n) for n in args.counts.split(",")):
        rng = np.random.default_rng(7)
        obstacles = [Sphere(rng.uniform([-2.0, -2.0, 0.0], [2.0, 2.0, 2.0]).tolist(), 0.05,
                            name=f"sphere{k}") for k in range(count)]
        avoidance_module.MAX_OBSTACLES = max(count, avoidance_module.MAX_OBSTACLES)
        start = time.perf_counter()
        avoidance = CollisionAvoidance(robot, obstacles)
        build = time.perf_counter() - start
        rows = median_time(lambda: avoidance.rows(robot.model, data))
        near = int(avoidance._boxes.near(*robot_box(avoidance, robot, data)).sum())
        before = resident_mb()
        controller: CJMController | None = CJMController(robot, backend="compiled", collisions=avoidance)
        controller.solve(q, twist)
        memory = resident_mb() - before
        step = median_time(lambda: controller.solve(q, twist))
        controller = None  # its workspace freed before the next count
        print(f"| {count} | {1e3 * build:.0f} | {1e3 * rows:.3f} | {1e3 * step:.3f} | {near} "
              f"| {memory:.0f} |", flush=True)


def robot_box(avoidance: CollisionAvoidance, robot, data) -> tuple[np.ndarray, np.ndarray]:
    """The box the broadphase meets the obstacles with: the robot's, grown by d_i."""
    from constraints.collision.broadphase import capsule_boxes

    starts, ends = avoidance._update(robot.model, data)
    count = avoidance._robot_count
    lower, upper = capsule_boxes(starts[:count], ends[:count], avoidance._radii[:count])
    reach = avoidance.detection_distance
    return lower.min(axis=0) - reach, upper.max(axis=0) + reach


if __name__ == "__main__":
    main()
