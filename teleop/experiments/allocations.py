"""Heap allocations per step for ``teleop bench`` (docs/design.md section 16, the
bench).

A malloc-counting shim (``alloc_counter.c``: ``malloc``, ``calloc``, ``realloc`` and the
aligned allocations counted, then handed to glibc) is compiled once with the C compiler
Python was built with (``sysconfig``'s ``CC``) and kept under the user's cache directory.
:func:`count_allocations` runs a bench problem's controllers in a subprocess with the shim
``LD_PRELOAD``-ed; the subprocess (this module's ``main``) reads the count through ctypes
around the steps. Without a compiler (or off Linux) :func:`counter_library` is None and
the bench says ``n/a``.

Per step, for each controller: ``called``, ``controller.solve(q, twist)`` from Python (the
count of a loop without the call taken off); ``floor``, the same step in its C++ loop
(``CompiledStep.time_steps``), as the difference between a loop over ``2 n`` steps and one
over ``n`` (what a call allocates once, its arrays, cancels).
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import os
import shlex
import subprocess
import sys
import sysconfig
import tempfile
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from teleop.controller_specs import make_controller

from .bench_problems import bench_configurations, bench_problem_named, bench_twist

#: the shim's C source, shipped with the package
COUNTER_SOURCE = Path(__file__).with_name("alloc_counter.c")
#: steps each controller takes before the count (caches filled, solvers warmed)
WARMUP_STEPS = 10
#: longest a problem's count may take (s)
COUNT_TIMEOUT_S = 600.0


@dataclass(frozen=True)
class StepAllocations:
    """Heap allocations per step of one controller: from Python, and in its C++ loop
    (None: the controller has none)."""

    called: float
    floor: float | None = None


def build_compiler() -> list[str]:
    """The C compiler command Python was built with (``sysconfig``'s ``CC``)."""
    return shlex.split(sysconfig.get_config_var("CC") or "cc")


def cache_directory() -> Path:
    """The user's cache directory for this package (``$XDG_CACHE_HOME``, else ``~/.cache``)."""
    root = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(root) / "cjm-teleop"


def counter_library(compiler: Sequence[str] | None = None) -> str | None:
    """The shim compiled with ``compiler`` (default :func:`build_compiler`), kept under
    :func:`cache_directory` by a hash of its source and the compiler command; None off
    Linux (no ``LD_PRELOAD``) or when it does not compile."""
    if not sys.platform.startswith("linux"):
        return None
    compiler = list(build_compiler() if compiler is None else compiler)
    digest = hashlib.sha256(COUNTER_SOURCE.read_bytes() + "\0".join(compiler).encode())
    library = cache_directory() / f"alloc_counter-{digest.hexdigest()[:16]}.so"
    if library.is_file():
        return str(library)
    try:
        library.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=library.parent) as scratch:
            built = Path(scratch) / library.name
            subprocess.run([*compiler, "-shared", "-fPIC", "-O2", "-o", str(built),
                            str(COUNTER_SOURCE)], check=True, capture_output=True, timeout=120)
            built.replace(library)
    except (OSError, subprocess.SubprocessError):
        return None
    return str(library)


def count_allocations(problem: str, controllers: Sequence[str], steps: int,
                      library: str) -> dict[str, StepAllocations]:
    """Per controller spec, its allocations per step on the bench problem ``problem``
    over ``steps`` of its configurations (:func:`main` in a subprocess with ``library``
    preloaded); empty, with a warning saying why, when the subprocess fails."""
    package_root = str(Path(__file__).resolve().parents[2])
    env = {**os.environ, "LD_PRELOAD": library,
           "PYTHONPATH": os.pathsep.join(filter(None, [package_root,
                                                       os.environ.get("PYTHONPATH")]))}
    with tempfile.TemporaryDirectory() as scratch:
        output = Path(scratch) / "allocations.json"
        try:
            run = subprocess.run([sys.executable, "-m", __name__, problem, str(steps),
                                  str(output), *controllers], env=env, capture_output=True,
                                 text=True, timeout=COUNT_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            warnings.warn(f"allocations of {problem} not counted: over {COUNT_TIMEOUT_S:g} s",
                          RuntimeWarning, stacklevel=2)
            return {}
        if run.returncode != 0 or not output.is_file():
            reason = (run.stderr.strip().splitlines() or ["no output"])[-1]
            warnings.warn(f"allocations of {problem} not counted: {reason}", RuntimeWarning,
                          stacklevel=2)
            return {}
        counted = json.loads(output.read_text(encoding="utf-8"))
    return {spec: StepAllocations(**entry) for spec, entry in counted.items()}


def allocation_counter(library: str) -> Callable[[], int]:
    """The preloaded shim's running count of allocations (ctypes)."""
    count = ctypes.CDLL(library).alloc_counter_count
    count.restype = ctypes.c_ulonglong
    count.argtypes = []
    return count


def measure(problem: str, controllers: Sequence[str], steps: int,
            count: Callable[[], int]) -> dict[str, StepAllocations]:
    """Each controller's :class:`StepAllocations` on ``problem``, read with ``count``
    (runs in the subprocess that preloads the shim)."""
    bench = bench_problem_named(problem)
    robot, constraints = bench.robot, bench.constraints
    configurations = bench_configurations(robot, constraints, WARMUP_STEPS + 2 * steps,
                                          base=bench.base)
    twist = bench_twist(robot, constraints, bench.base)
    counted = configurations[WARMUP_STEPS:WARMUP_STEPS + steps]
    before = count()
    for _ in counted:
        pass
    loop = count() - before
    results = {}
    for spec in controllers:
        controller = make_controller(spec, robot, constraints, acceleration_limit=None)
        if bench.collisions is not None:
            controller.set_collisions(bench.collisions)
        for q in configurations[:WARMUP_STEPS]:
            controller.solve(q, twist)
        before = count()
        for q in counted:
            controller.solve(q, twist)
        called = (count() - before - loop) / steps
        results[spec] = StepAllocations(called, floor_allocations(controller, configurations,
                                                                  twist, steps, count))
    return results


def floor_allocations(controller: object, configurations: np.ndarray, twist: np.ndarray,
                      steps: int, count: Callable[[], int]) -> float | None:
    """Allocations per step of ``controller``'s C++ loop (``step.time_steps``): a loop
    over ``2 steps`` configurations less one over ``steps``, per step; None without one."""
    time_steps = getattr(getattr(controller, "step", None), "time_steps", None)
    if time_steps is None:
        return None
    twists = np.tile(twist, (len(configurations), 1))
    if time_steps(configurations[:WARMUP_STEPS], twists[:WARMUP_STEPS]) is None:
        return None
    totals = []
    for length in (steps, 2 * steps):
        before = count()
        time_steps(configurations[WARMUP_STEPS:WARMUP_STEPS + length],
                   twists[WARMUP_STEPS:WARMUP_STEPS + length])
        totals.append(count() - before)
    return (totals[1] - totals[0]) / steps


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m teleop.experiments.allocations PROBLEM STEPS OUTPUT SPEC...`` with the
    shim preloaded: writes each spec's :class:`StepAllocations` to OUTPUT (JSON)."""
    problem, steps, output, *controllers = sys.argv[1:] if argv is None else argv
    library = os.environ.get("LD_PRELOAD", "").split(os.pathsep)[0]
    results = measure(problem, controllers, int(steps), allocation_counter(library))
    Path(output).write_text(json.dumps({spec: asdict(entry) for spec, entry in results.items()}),
                            encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
