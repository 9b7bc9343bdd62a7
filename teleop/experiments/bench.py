"""One-step timing of every controller (``teleop bench``): the built-in robots, then
scaling over generated chains and numbers of constraints, all in one process.

Every controller of a problem solves the same configurations with the same twist, so their
commands are compared too: each one's largest ``|qd - qd_ref|`` against the first
controller listed (docs/design.md section 15.3). The solvers' console output is kept off the
console (section 15.5), in each timing's ``solver_messages``.

Beside the built-in robots (one hole on each constrained link) the bench has a problem
for each other constraint type, ``sda10f/plane``, ``sda10f/lock`` and ``sda10f/barrier``,
and the generated chains of the scaling runs (:mod:`.bench_problems`). Each row has the
median and the p99; a compiled CJM row also the same step timed in a C++ loop (the C++
floor, ``CompiledStep.time_steps``); every row its heap allocations per step
(:mod:`.allocations`); :func:`target_checks` sets the ratios against their targets
(docs/design.md section 16, the bench).

With a plant (``--plant``, docs/design.md section 17) each built-in robot's controllers
are also timed through a control period's tick, in the same run: the step followed by the
kinematic integration (``pin.integrate``), and the step followed by the plant's period
(its physics substeps, then the integration of the velocity it returns).
"""

from __future__ import annotations

import collections
import json
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.collision import CollisionAvoidance
from teleop.controller_specs import default_specs, make_controller
from teleop.limits import MAX_BENCH_ITERATIONS
from teleop.robots import BUILTIN_ROBOTS, Robot

from .allocations import StepAllocations, count_allocations, counter_library
# DEFAULT_HOLE_DISTANCE and _hole_rows: read from here by tests/test_compiled_step.py
from .bench_problems import (CONSTRAINT_PROBLEMS, DEFAULT_HOLE_DISTANCE,  # noqa: F401
                             SCALING_DOFS, SCALING_HOLES, _hole_rows, bench_configurations,
                             bench_problem_named, bench_twist, known_problems, problem_labels,
                             scaling_problems)
from .metrics_table import format_status_counts
from teleop.plants.choice import PlantChoice
from .solver_output import SolverOutputCapture

SCALING_CONTROLLERS = default_specs("scaling")
#: most steps whose heap allocations are counted per controller (after a warm-up)
ALLOCATION_STEPS = 200


@dataclass(frozen=True)
class StepTiming:
    """Timing of ``solve(q, twist)`` for one controller on one problem (microseconds)."""

    robot: str
    controller: str
    dof: int
    constraint_rows: int
    median_us: float
    p99_us: float
    max_us: float
    iterations: int
    max_constraint_residual: float  # m/s, max |A qd - b| over the timed steps
    method: str  # what the controller did (analytical / general / qp:... / mink:...)
    status_counts: dict[str, int]  # timed steps per step status (ok, scaled, ...)
    #: max over the configurations of max_j |qd_j - qd_ref,j| against the problem's first
    #: controller (rad/s; 0 for that one)
    joint_velocity_deviation_max: float = 0.0
    solver_messages: dict[str, int] = field(default_factory=dict)  # kept off the console
    plant: str = "kinematic"  # the plant of the tick timings (bench_ticks)
    #: median of the step plus ``pin.integrate``, and of the step plus the plant's period
    #: (its physics and the integration), over the same configurations (us; 0: not timed)
    kinematic_tick_median_us: float = 0.0
    plant_tick_median_us: float = 0.0
    #: the same step in a C++ loop, no Python between the steps (CompiledStep.time_steps;
    #: None: the controller has no such loop, or its step is not one C++ call)
    floor_median_us: float | None = None
    floor_p99_us: float | None = None
    #: heap allocations per step of that C++ loop and of ``solve`` called from Python
    #: (:mod:`.allocations`; None: not counted, e.g. without a C compiler)
    floor_allocations: float | None = None
    called_allocations: float | None = None
    active_barrier_steps: int = 0  # timed steps whose command holds a barrier (CJM)

    @property
    def p99_over_median(self) -> float:
        return self.p99_us / self.median_us

    @property
    def called_over_floor(self) -> float | None:
        """The Python-called median over the C++ floor's: the binding's overhead."""
        return None if not self.floor_median_us else self.median_us / self.floor_median_us


def time_steps(step: Callable[[np.ndarray], None], configurations: np.ndarray,
               warmup: int, record: Callable[[int], None] | None = None) -> np.ndarray:
    """Per-call wall time (us) of ``step(q)`` over ``configurations`` after a warm-up;
    ``record(i)``, called after the clock stops, reads what step ``i`` did."""
    for q in configurations[:warmup]:
        step(q)
    times = np.empty(len(configurations))
    clock = time.perf_counter_ns
    for i, q in enumerate(configurations):
        start = clock()
        step(q)
        times[i] = (clock() - start) * 1e-3
        if record is not None:
            record(i)
    return times


def bench_problem(robot: Robot, holes: Sequence[Constraint], spec: str, iterations: int,
                  warmup: int, seed: int = 0, label: str | None = None,
                  base: np.ndarray | None = None,
                  collisions: CollisionAvoidance | None = None) -> tuple[StepTiming, np.ndarray]:
    """Time one controller on ``holes`` (and ``collisions``' pairs) over configurations
    near ``base`` (default: the robot's home); returns the timing and the commands, one
    row per configuration. The configurations are unrelated, so no previous command
    exists: the acceleration limits are off (their cost shows in the loop's tick,
    docs/design.md 8.4). A controller whose step runs in a C++ loop too
    (``controller.step.time_steps``) is timed there after, on the same configurations."""
    controller = make_controller(spec, robot, holes, acceleration_limit=None)
    if collisions is not None:
        controller.set_collisions(collisions)
    configurations = bench_configurations(robot, holes, iterations, seed, base)
    twist = bench_twist(robot, holes, base)
    residual = 0.0
    barrier_steps = 0
    statuses: collections.Counter[str] = collections.Counter()
    commands = np.empty((iterations, robot.model.nv))
    command = np.empty(0)

    def step(q: np.ndarray) -> None:  # the timed call: the controller's step only
        nonlocal command
        command = controller.solve(q, twist)

    def record(i: int) -> None:
        nonlocal residual, barrier_steps
        commands[i] = command
        residual = max(residual, controller.info.equality_residual)
        barrier_steps += bool(controller.info.active_barriers)
        statuses[controller.info.status.value] += 1

    times = time_steps(step, configurations, warmup, record)
    floor = time_floor(controller, configurations, twist, warmup)
    timing = StepTiming(robot=label or robot.name, controller=spec, dof=robot.model.nv,
                        constraint_rows=sum(h.dim for h in holes),
                        median_us=float(np.median(times)),
                        p99_us=float(np.percentile(times, 99)), max_us=float(times.max()),
                        iterations=iterations, max_constraint_residual=residual,
                        method=controller.info.method, status_counts=dict(statuses),
                        active_barrier_steps=barrier_steps,
                        floor_median_us=None if floor is None else float(np.median(floor)),
                        floor_p99_us=None if floor is None else float(np.percentile(floor, 99)))
    return timing, commands


def time_floor(controller: object, configurations: np.ndarray, twist: np.ndarray,
               warmup: int) -> np.ndarray | None:
    """Per-step wall time (us) of ``controller``'s step in its C++ loop over
    ``configurations`` with ``twist`` after a warm-up (``CompiledStep.time_steps``);
    None for a controller without one."""
    time_steps_in_cpp = getattr(getattr(controller, "step", None), "time_steps", None)
    if time_steps_in_cpp is None:
        return None
    twists = np.tile(twist, (len(configurations), 1))
    if time_steps_in_cpp(configurations[:warmup], twists[:warmup]) is None:
        return None
    return time_steps_in_cpp(configurations, twists) * 1e-3


def bench_ticks(robot: Robot, holes: Sequence[Constraint], spec: str, configurations: np.ndarray,
                plant: PlantChoice, dt: float = 1e-3) -> tuple[float, float]:
    """Medians (us) over ``configurations`` of a control period's tick on the kinematic
    plant (``solve``, then ``pin.integrate``) and on ``plant`` (``solve``, then the plant's
    ``advance``: its period and the integration of its velocity, as the loop's), each
    configuration timed both ways in turn; the plant starts at home and keeps its own
    state."""
    controller = make_controller(spec, robot, holes, dt=dt, acceleration_limit=None)
    plant.apply_wall(holes)
    simulated = plant.make(robot, dt)
    twist = bench_twist(robot, holes)
    model = robot.model
    clock = time.perf_counter_ns
    kinematic, physical = np.empty(len(configurations)), np.empty(len(configurations))
    for i, q in enumerate(configurations):
        start = clock()
        pin.integrate(model, q, controller.solve(q, twist) * dt)
        middle = clock()
        command = controller.solve(q, twist)
        if simulated is None:
            pin.integrate(model, q, command * dt)
        else:  # as the loop's period: the plant's velocity and the configuration reached
            simulated.advance(command, q, holes, dt)
        kinematic[i], physical[i] = (middle - start) * 1e-3, (clock() - middle) * 1e-3
    return float(np.median(kinematic)), float(np.median(physical))


def bench_controllers(robot: Robot, holes: Sequence[Constraint], specs: Sequence[str],
                      iterations: int, warmup: int, label: str | None = None,
                      plant: PlantChoice | None = None, base: np.ndarray | None = None,
                      collisions: CollisionAvoidance | None = None) -> list[StepTiming]:
    """:func:`bench_problem` for every spec on one problem, each with its largest joint-
    velocity deviation from the first spec's commands and its solvers' console output;
    with ``plant``, also its :func:`bench_ticks` over the same configurations."""
    timings = []
    reference = None
    with SolverOutputCapture() as capture:
        for spec in specs:
            timing, commands = bench_problem(robot, holes, spec, iterations, warmup, label=label,
                                             base=base, collisions=collisions)
            reference = commands if reference is None else reference
            ticks: dict[str, Any] = {}
            if plant is not None:
                kinematic, physical = bench_ticks(robot, holes, spec,
                                                  bench_configurations(robot, holes, iterations),
                                                  plant)
                ticks = dict(plant=plant.kind, kinematic_tick_median_us=kinematic,
                             plant_tick_median_us=physical)
            timings.append(replace(
                timing, joint_velocity_deviation_max=float(np.max(np.abs(commands - reference))),
                solver_messages=capture.collect(), **ticks))
    return timings


def check_iterations(iterations: int) -> int:
    """``iterations`` as a count of timed steps in [1, :data:`MAX_BENCH_ITERATIONS`]."""
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)) \
            or not 1 <= iterations <= MAX_BENCH_ITERATIONS:
        raise ValueError(f"iterations must be an integer in [1, {MAX_BENCH_ITERATIONS}], "
                         f"got {iterations!r}")
    return int(iterations)


def run_bench(robots: Sequence[str] = ("sda10f", "ur5_instrument"),
              controllers: Sequence[str] = default_specs("bench"),
              iterations: int = 2000, plant: PlantChoice | None = None,
              allocations: bool = True) -> list[StepTiming]:
    """The named problems (:func:`known_problems`): a built-in robot with one hole on each
    constrained link (the paper's 6-before/2-after case, on each arm of the dual robots;
    the dual robot's arms close together too, without and with collision avoidance,
    :func:`problem_labels`), a constraint problem (:data:`CONSTRAINT_PROBLEMS`) or a
    generated chain of the scaling runs; with ``plant``, each built-in robot's controllers'
    :func:`bench_ticks` too; with ``allocations``, each row's heap allocations per step
    where a C compiler is at hand (:mod:`.allocations`). An unknown name or an iteration
    count outside [1, :data:`~teleop.limits.MAX_BENCH_ITERATIONS`] raises ``ValueError``
    before any run."""
    check_iterations(iterations)
    if plant is not None and plant.kind == "ros2":
        raise ValueError("the bench commands random configurations' steps: not on a ROS 2 "
                         "robot (--plant kinematic or mujoco)")
    if isinstance(robots, str):
        raise ValueError(f"robots must be a list of built-in robot names, got {robots!r}")
    known = known_problems()
    for name in robots:
        if name not in known:
            raise ValueError(f"unknown robot {name!r}: the bench runs the built-in robots "
                             f"{', '.join(BUILTIN_ROBOTS)}, the problems "
                             f"{', '.join(CONSTRAINT_PROBLEMS)} and the chains "
                             f"{', '.join(scaling_problems())}")
    library = counter_library() if allocations else None
    warmup = max(1, iterations // 10)
    results = []
    for name in robots:
        for label in problem_labels(name):
            results += bench_named(label, controllers, iterations, warmup,
                                   plant=plant if label in BUILTIN_ROBOTS else None,
                                   library=library)
    return results


def bench_named(label: str, controllers: Sequence[str], iterations: int, warmup: int,
                plant: PlantChoice | None = None,
                library: str | None = None) -> list[StepTiming]:
    """:func:`bench_controllers` on the problem ``label``; with the allocation counter
    ``library`` (:func:`~.allocations.counter_library`), each row's allocations per step
    over at most :data:`ALLOCATION_STEPS` of the same configurations."""
    problem = bench_problem_named(label)
    timings = bench_controllers(problem.robot, problem.constraints, controllers, iterations,
                                warmup, label=label, plant=plant, base=problem.base,
                                collisions=problem.collisions)
    if library is None:
        return timings
    counted = count_allocations(label, controllers, min(iterations, ALLOCATION_STEPS), library)
    return [with_allocations(timing, counted.get(timing.controller)) for timing in timings]


def with_allocations(timing: StepTiming, counted: StepAllocations | None) -> StepTiming:
    """``timing`` with its allocations per step (as it is when they were not counted)."""
    if counted is None:
        return timing
    return replace(timing, floor_allocations=counted.floor, called_allocations=counted.called)


def run_scaling(iterations: int = 300, controllers: Sequence[str] = SCALING_CONTROLLERS,
                dofs: Sequence[int] = SCALING_DOFS, holes: Sequence[int] = SCALING_HOLES,
                allocations: bool = True) -> list[StepTiming]:
    """Generated chains: 1 hole on 8..64 DoF, then 1..8 holes on the 32-DoF chain
    (:func:`scaling_problems`), each row with its allocations per step as in
    :func:`run_bench`."""
    library = counter_library() if allocations else None
    warmup = max(1, iterations // 10)
    return [timing for label in scaling_problems(dofs, holes)
            for timing in bench_named(label, controllers, iterations, warmup, library=library)]


def mink_ratios(results: Sequence[StepTiming]) -> dict[tuple[str, str], float]:
    """``mink median / controller median`` per (problem, controller), same run."""
    return speedups(results, "mink")


def speedups(results: Sequence[StepTiming], reference_prefix: str) -> dict[tuple[str, str], float]:
    """``reference median / controller median`` per (problem, controller), same run; the
    reference is the problem's first controller whose spec starts with ``reference_prefix``
    (``"mink"``, ``"qp:daqp"``)."""
    reference = {}
    for r in results:
        if r.controller.startswith(reference_prefix) and (r.robot, r.constraint_rows) not in reference:
            reference[(r.robot, r.constraint_rows)] = r.median_us
    return {(r.robot, r.controller): reference[(r.robot, r.constraint_rows)] / r.median_us
            for r in results if (r.robot, r.constraint_rows) in reference}


#: The ratios a compiled CJM row is held to (docs/design.md section 16, the bench): its
#: median over the same controller's on the ``sda10f`` hole, at most
HOLE_RATIO_TARGETS = {"sda10f/plane": 1.5, "sda10f/lock": 1.5, "sda10f/barrier": 1.5,
                      "sda10f_dual": 2.5, "sda10f_dual/collisions": 5.0, "chain64": 5.0}
#: p99 over median, at most, on these problems
P99_TARGET, P99_PROBLEMS = 3.0, CONSTRAINT_PROBLEMS
#: how many times faster than ``mink:daqp`` and ``qp:daqp`` on the same problem, at least
MINK_TARGET, QP_DAQP_TARGET = 25.0, 8.0
#: the Python-called median over the C++ floor's, at most
FLOOR_TARGET = 2.0
#: the problem every ``HOLE_RATIO_TARGETS`` ratio divides by
HOLE_PROBLEM = "sda10f"


@dataclass(frozen=True)
class TargetCheck:
    """One ratio of one row against its target: ``value <= limit`` (``value >= limit``
    with ``at_least``)."""

    problem: str
    controller: str
    measure: str
    value: float
    limit: float
    at_least: bool = False

    @property
    def met(self) -> bool:
        return self.value >= self.limit if self.at_least else self.value <= self.limit


def held_to_targets(timing: StepTiming) -> bool:
    """The rows the targets are for: the CJM's compiled step (``cjm:python``, the readable
    reference, is not)."""
    return timing.controller.startswith("cjm") and timing.controller != "cjm:python"


def hole_medians(results: Sequence[StepTiming]) -> dict[str, float]:
    """Each controller's median on :data:`HOLE_PROBLEM` in ``results`` (the first row)."""
    medians: dict[str, float] = {}
    for r in results:
        if r.robot == HOLE_PROBLEM:
            medians.setdefault(r.controller, r.median_us)
    return medians


def target_checks(results: Sequence[StepTiming]) -> list[TargetCheck]:
    """Every target ratio of ``results``' CJM rows (:func:`held_to_targets`) that this run
    measured, in the rows' order: the median over the hole's, p99 over median, the
    speed-ups over ``mink:daqp`` and ``qp:daqp``, the Python-called median over the C++
    floor's."""
    hole, mink, daqp = hole_medians(results), mink_ratios(results), speedups(results, "qp:daqp")
    checks = []
    for r in filter(held_to_targets, results):
        key = (r.robot, r.controller)
        if r.robot in HOLE_RATIO_TARGETS and r.controller in hole:
            checks.append(TargetCheck(r.robot, r.controller, f"median / {HOLE_PROBLEM} hole",
                                      r.median_us / hole[r.controller],
                                      HOLE_RATIO_TARGETS[r.robot]))
        if r.robot in P99_PROBLEMS:
            checks.append(TargetCheck(r.robot, r.controller, "p99 / median", r.p99_over_median,
                                      P99_TARGET))
        if key in mink:
            checks.append(TargetCheck(r.robot, r.controller, "x mink:daqp", mink[key],
                                      MINK_TARGET, at_least=True))
        if key in daqp:
            checks.append(TargetCheck(r.robot, r.controller, "x qp:daqp", daqp[key],
                                      QP_DAQP_TARGET, at_least=True))
        if r.called_over_floor is not None:
            checks.append(TargetCheck(r.robot, r.controller, "called / C++ floor",
                                      r.called_over_floor, FLOOR_TARGET))
    return checks


def _number(value: float | None, digits: str = ".1f") -> str:
    return "n/a" if value is None else format(value, digits)


def format_table(results: Sequence[StepTiming]) -> str:
    """One line per timing, then the barriers held, the plant's ticks and the targets
    (:func:`format_targets`).
    ``p99/med``: p99 over median; ``floor us``: the same step in a C++ loop, ``x floor``
    the median over it; ``alloc C++``/``alloc py``: heap allocations per step in that loop
    and from Python; ``qd dev``: the joint-velocity deviation from the problem's first
    controller (rad/s)."""
    ratios, daqp = mink_ratios(results), speedups(results, "qp:daqp")
    lines = [(f"{'problem':<24}{'dof':>4}{'rows':>5}  {'controller':<13}{'median us':>10}"
              f"{'p99 us':>9}{'p99/med':>8}{'max us':>10}{'floor us':>9}{'x floor':>8}"
              f"{'alloc C++':>10}{'alloc py':>9}{'x mink':>8}{'x daqp':>8}{'residual':>10}"
              f"{'qd dev':>10}  {'method':<12}statuses")]
    for r in results:
        ratio, daqp_ratio = ratios.get((r.robot, r.controller)), daqp.get((r.robot, r.controller))
        lines.append(
            f"{r.robot:<24}{r.dof:>4}{r.constraint_rows:>5}  {r.controller:<13}{r.median_us:>10.1f}"
            f"{r.p99_us:>9.1f}{r.p99_over_median:>8.1f}{r.max_us:>10.1f}"
            f"{'' if r.floor_median_us is None else f'{r.floor_median_us:.1f}':>9}"
            f"{'' if r.called_over_floor is None else f'{r.called_over_floor:.1f}':>8}"
            f"{_number(r.floor_allocations, '.3g') if r.floor_median_us is not None else '':>10}"
            f"{_number(r.called_allocations, '.3g'):>9}"
            f"{'' if ratio is None else f'{ratio:.1f}':>8}"
            f"{'' if daqp_ratio is None else f'{daqp_ratio:.1f}':>8}"
            f"{r.max_constraint_residual:>10.1e}{r.joint_velocity_deviation_max:>10.1e}  "
            f"{r.method:<12}{format_status_counts(r.status_counts)}")
    barriers = [r for r in results
                if r.robot.endswith("/barrier") and r.controller.startswith("cjm")]
    if barriers:
        lines += [""] + [f"{r.robot} {r.controller}: the barrier held in {r.active_barrier_steps} "
                         f"of {r.iterations} steps ({r.active_barrier_steps / r.iterations:.0%})"
                         for r in barriers]
    ticks = [r for r in results if r.plant_tick_median_us > 0]
    if ticks:
        lines += ["", f"{'problem':<20}  {'controller':<13}{'kinematic tick us':>18}"
                      f"{ticks[0].plant + ' tick us':>18}{'ratio':>8}"]
        lines += [f"{r.robot:<20}  {r.controller:<13}{r.kinematic_tick_median_us:>18.1f}"
                  f"{r.plant_tick_median_us:>18.1f}"
                  f"{r.plant_tick_median_us / r.kinematic_tick_median_us:>8.1f}" for r in ticks]
    lines += format_targets(target_checks(results))
    return "\n".join(lines)


#: the targets' columns under the table: (measure, header)
TARGET_COLUMNS = (("median / sda10f hole", "/ hole"), ("p99 / median", "p99/med"),
                  ("x mink:daqp", "x mink"), ("x qp:daqp", "x daqp"),
                  ("called / C++ floor", "/ floor"))


def format_targets(checks: Sequence[TargetCheck]) -> list[str]:
    """The checks as lines under the table: one per CJM row, a column per ratio, ``*``
    after a ratio that misses its target (no lines without checks)."""
    if not checks:
        return []
    rows: dict[tuple[str, str], dict[str, TargetCheck]] = {}
    for check in checks:
        rows.setdefault((check.problem, check.controller), {})[check.measure] = check
    hole_limits = ", ".join(f"{problem} {limit:g}"
                            for problem, limit in HOLE_RATIO_TARGETS.items())
    lines = ["", f"targets (docs/design.md section 16, the bench), this run: "
                 f"{sum(c.met for c in checks)} of {len(checks)} met; * marks a miss",
             f"  / hole: the median over the same controller's on {HOLE_PROBLEM}, at most "
             f"{hole_limits}",
             f"  p99/med at most {P99_TARGET:g}; x mink, x daqp at least {MINK_TARGET:g}, "
             f"{QP_DAQP_TARGET:g}; / floor: the median over the C++ floor's, at most "
             f"{FLOOR_TARGET:g}",
             f"{'problem':<24}  {'controller':<13}"
             + "".join(f"{header:>10}" for _, header in TARGET_COLUMNS)]
    for (problem, controller), measured in rows.items():
        cells = [measured.get(measure) for measure, _ in TARGET_COLUMNS]
        lines.append((f"{problem:<24}  {controller:<13}" + "".join(
            f"{'' if c is None else f'{c.value:.2f}' + (' ' if c.met else '*'):>10}"
            for c in cells)).rstrip())
    return lines


def check_json_path(path: str) -> None:
    """``ValueError`` unless :func:`write_json` can write ``path``: asked before minutes of
    benchmarking (a file it makes to find out is removed)."""
    target = Path(path)
    if target.is_dir():
        raise ValueError(f"--json {path!r} is a directory")
    existed = target.exists()
    try:
        with target.open("a", encoding="utf-8"):
            pass
    except OSError as error:
        raise ValueError(f"cannot write --json {path!r}: {error.strerror or error}") from None
    if not existed:
        target.unlink()


def write_json(results: Sequence[StepTiming], path: str) -> None:
    """One object per row: its fields, the speed-ups over ``mink`` and ``qp:daqp``, its
    ratios (p99 over median, the median over the C++ floor's and over the same
    controller's on the ``sda10f`` hole) and its :func:`target_checks`."""
    ratios = mink_ratios(results)
    daqp = speedups(results, "qp:daqp")
    hole = hole_medians(results)
    checks: dict[tuple[str, str], list[dict]] = collections.defaultdict(list)
    for check in target_checks(results):
        checks[(check.problem, check.controller)].append({**asdict(check), "met": check.met})
    rows = [{**asdict(r), "speedup_vs_mink": ratios.get((r.robot, r.controller)),
             "speedup_vs_qp_daqp": daqp.get((r.robot, r.controller)),
             "p99_over_median": r.p99_over_median, "called_over_floor": r.called_over_floor,
             "median_over_sda10f_hole": (r.median_us / hole[r.controller]
                                         if r.controller in hole else None),
             "targets": checks.get((r.robot, r.controller), [])} for r in results]
    try:
        with open(path, "w", encoding="utf-8") as handle:
            json.dump(rows, handle, indent=2)
    except OSError as error:
        raise ValueError(f"cannot write --json {path!r}: {error.strerror or error}") from None
