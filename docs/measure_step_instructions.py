"""Instructions per controller step, counted by valgrind's callgrind (issue 37, "no
controller's step slower"; docs/design.md section 16): a count the machine's load does not
move, where ``teleop bench``'s wall-clock medians move by more than a regression of a few
per cent on these 2 shared cores (and ``perf stat`` has no hardware counters in this VM).

Each problem runs in a process of its own under callgrind: the bench's controller, its
configurations and its twist (teleop/experiments/bench_problems.py), 200 warm-up steps, then
``--steps`` calls of ``controller.solve`` driven by ``itertools.starmap``, whose C function
``starmap_next`` is the only one callgrind collects in (``--toggle-collect``): the count is
exactly those calls' (Python and C++), nothing of the set-up. Printed per step: every
instruction of the call, and those of the C++ pipeline's kinematics and step
(``cjm::Pipeline::prepare`` and ``finish``; 0 for a controller without them), so that a
change in the Python around the step shows apart from the step's own.

Run:  OPENBLAS_NUM_THREADS=1 python docs/measure_step_instructions.py
      [--problems sda10f,sda10f/lock,sda10f_dual] [--controller cjm] [--steps 200]
(about a minute a problem; needs valgrind and callgrind_annotate; it counts the checkout
it lies in: copy it into another checkout's docs/ to count that one)
"""

from __future__ import annotations

import argparse
import collections
import itertools
import os
import re
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

#: the warm-up steps before the counted ones (the caches, the interpreter's specializations)
WARMUP_STEPS = 200
#: the C++ functions whose inclusive count is the compiled step's own
CPP_STEP = ("cjm::Pipeline::prepare(", "cjm::Pipeline::finish(")


def run_steps(problem: str, controller_spec: str, steps: int) -> None:
    """The counted run (in the process callgrind watches): ``steps`` calls of the
    controller's ``solve`` over the bench's configurations of ``problem``."""
    from teleop.controller_specs import make_controller
    from teleop.experiments.bench_problems import (bench_configurations, bench_problem_named,
                                                   bench_twist)

    named = bench_problem_named(problem)
    controller = make_controller(controller_spec, named.robot, named.constraints,
                                 acceleration_limit=None)
    if named.collisions is not None:
        controller.set_collisions(named.collisions)
    configurations = bench_configurations(named.robot, named.constraints, 2000, 0, named.base)
    twist = bench_twist(named.robot, named.constraints, named.base)
    for q in configurations[:WARMUP_STEPS]:
        controller.solve(q, twist)
    calls = [(configurations[i % len(configurations)], twist) for i in range(steps)]
    collections.deque(itertools.starmap(controller.solve, calls), maxlen=0)


def annotated(path: str, inclusive: bool) -> str:
    """``callgrind_annotate``'s listing of the profile at ``path``."""
    return subprocess.run(["callgrind_annotate", f"--inclusive={'yes' if inclusive else 'no'}",
                           "--threshold=100", path], capture_output=True, text=True,
                          check=True).stdout


def count(line: str) -> int:
    """The instruction count a ``callgrind_annotate`` line starts with."""
    return int(line.split()[0].replace(",", ""))


def measure(problem: str, controller_spec: str, steps: int) -> tuple[float, float]:
    """Instructions per step of ``problem``'s ``controller_spec``: the whole call and the
    C++ pipeline's (:data:`CPP_STEP`)."""
    with tempfile.TemporaryDirectory() as directory:
        profile = os.path.join(directory, "callgrind.out")
        subprocess.run(["valgrind", "--tool=callgrind", "--toggle-collect=starmap_next",
                        f"--callgrind-out-file={profile}", sys.executable, __file__, "--run",
                        problem, controller_spec, str(steps)],
                       check=True, capture_output=True,
                       env={**os.environ, "PYTHONHASHSEED": "0", "OPENBLAS_NUM_THREADS": "1"})
        totals = [line for line in annotated(profile, False).splitlines()
                  if "PROGRAM TOTALS" in line]
        step_lines = [line for line in annotated(profile, True).splitlines()
                      if re.search(r"\d \(", line) and any(name in line for name in CPP_STEP)]
    return count(totals[0]) / steps, sum(map(count, step_lines)) / steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--problems", default="sda10f,sda10f/lock,sda10f_dual",
                        help="comma-separated teleop bench problems")
    parser.add_argument("--controller", default="cjm", help="a teleop bench controller")
    parser.add_argument("--steps", type=int, default=200, help="counted steps a problem")
    parser.add_argument("--run", nargs=3, metavar=("PROBLEM", "CONTROLLER", "STEPS"),
                        help=argparse.SUPPRESS)  # the counted process itself
    arguments = parser.parse_args()
    if arguments.run:
        problem, controller_spec, steps = arguments.run
        run_steps(problem, controller_spec, int(steps))
        return
    if arguments.steps < 1:
        parser.error("--steps must be at least 1")
    print(f"{'problem':24s} {'controller':12s} {'instructions/step':>18s} {'C++ step':>10s}")
    for problem in arguments.problems.split(","):
        whole, cpp = measure(problem, arguments.controller, arguments.steps)
        print(f"{problem:24s} {arguments.controller:12s} {whole:18.0f} {cpp:10.0f}", flush=True)


if __name__ == "__main__":
    main()
