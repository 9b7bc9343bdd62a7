"""One-step timing of every controller (``teleop bench``): the built-in robots, then
scaling over generated chains and numbers of constraints, all in one process.

Every controller of a problem solves the same configurations with the same twist, so their
commands are compared too: each one's largest ``|qd - qd_ref|`` against the first
controller listed (docs/design.md section 15.3). The solvers' console output is kept off the
console (section 15.5), in each timing's ``solver_messages``.

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
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from constraints import Hole
from constraints.collision import CollisionAvoidance
from teleop.controller_specs import default_specs, make_controller
from teleop.limits import MAX_BENCH_ITERATIONS
from teleop.robots import BUILTIN_ROBOTS, Robot, load_robot
from teleop.robots.chains import hole_links, load_chain

from .metrics_table import format_status_counts
from teleop.plants.choice import PlantChoice
from .solver_output import SolverOutputCapture

#: hole distance along the constrained link of each built-in robot (m)
DEFAULT_HOLE_DISTANCE = {"sda10f": 0.08, "ur5_instrument": 0.20, "sda10f_dual": 0.08,
                         "sda10f_dual_mobile": 0.08}

#: A teleoperation-sized body twist of the first EE (a few mm/s, mrad/s): no joint near
#: its velocity limit, so every controller solves the plain constrained problem.
BENCH_TWIST = (0.001, -0.002, 0.0015, 0.005, -0.003, 0.002)
SCALING_DOFS = (8, 16, 32, 64)
SCALING_HOLES = (1, 2, 4, 8)
SCALING_CONTROLLERS = default_specs("scaling")


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


def bench_problem(robot: Robot, holes: Sequence[Hole], spec: str, iterations: int,
                  warmup: int, seed: int = 0, label: str | None = None,
                  base: np.ndarray | None = None,
                  collisions: CollisionAvoidance | None = None) -> tuple[StepTiming, np.ndarray]:
    """Time one controller on ``holes`` (and ``collisions``' pairs) over configurations
    near ``base`` (default: the robot's home); returns the timing and the commands, one
    row per configuration. The configurations are unrelated, so no previous command
    exists: the acceleration limits are off (their cost shows in the loop's tick,
    docs/design.md 8.4)."""
    controller = make_controller(spec, robot, holes, acceleration_limit=None)
    if collisions is not None:
        controller.set_collisions(collisions)
    configurations = bench_configurations(robot, holes, iterations, seed, base)
    twist = bench_twist(robot, holes, base)
    residual = 0.0
    statuses: collections.Counter[str] = collections.Counter()
    commands = np.empty((iterations, robot.model.nv))
    command = np.empty(0)

    def step(q: np.ndarray) -> None:  # the timed call: the controller's step only
        nonlocal command
        command = controller.solve(q, twist)

    def record(i: int) -> None:
        nonlocal residual
        commands[i] = command
        residual = max(residual, controller.info.equality_residual)
        statuses[controller.info.status.value] += 1

    times = time_steps(step, configurations, warmup, record)
    timing = StepTiming(robot=label or robot.name, controller=spec, dof=robot.model.nv,
                        constraint_rows=sum(h.dim for h in holes),
                        median_us=float(np.median(times)),
                        p99_us=float(np.percentile(times, 99)), max_us=float(times.max()),
                        iterations=iterations, max_constraint_residual=residual,
                        method=controller.info.method, status_counts=dict(statuses))
    return timing, commands


def bench_ticks(robot: Robot, holes: Sequence[Hole], spec: str, configurations: np.ndarray,
                plant: PlantChoice, dt: float = 1e-3) -> tuple[float, float]:
    """Medians (us) over ``configurations`` of a control period's tick on the kinematic
    plant (``solve``, then ``pin.integrate``) and on ``plant`` (``solve``, then the plant's
    ``actuate``, then ``pin.integrate`` of the velocity it returns), each configuration
    timed both ways in turn; the plant starts at home and keeps its own state."""
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
        moved = command if simulated is None else simulated.actuate(command, q, holes)
        pin.integrate(model, q, moved * dt)
        kinematic[i], physical[i] = (middle - start) * 1e-3, (clock() - middle) * 1e-3
    return float(np.median(kinematic)), float(np.median(physical))


def bench_configurations(robot: Robot, holes: Sequence[Hole], iterations: int,
                         seed: int = 0, base: np.ndarray | None = None) -> np.ndarray:
    """``iterations`` configurations near ``base`` (default: home), a little off the holes
    (<= 1e-3 rad or m per velocity coordinate: sub-millimetre drift to correct), on the
    configuration manifold (nq != nv on a base)."""
    base = robot.q_home if base is None else base
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-1e-3, 1e-3, (iterations, robot.model.nv))
    rows = _hole_rows(robot, holes, base)
    if len(rows) + robot.task_size > robot.model.nv:  # the twists over-determine qd: stay
        offsets -= offsets @ rows.T @ np.linalg.pinv(rows).T  # on the holes, to first order
    return np.array([pin.integrate(robot.model, base, offset) for offset in offsets])


def bench_controllers(robot: Robot, holes: Sequence[Hole], specs: Sequence[str],
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
            ticks = {}
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
              iterations: int = 2000, plant: PlantChoice | None = None) -> list[StepTiming]:
    """The built-in robots, one hole on each constrained link (the paper's 6-before/2-after
    case, on each arm of the dual robots); with ``plant``, each controller's
    :func:`bench_ticks` too. An unknown robot or an iteration count outside
    [1, :data:`~teleop.limits.MAX_BENCH_ITERATIONS`] raises ``ValueError`` before any run."""
    check_iterations(iterations)
    if isinstance(robots, str):
        raise ValueError(f"robots must be a list of built-in robot names, got {robots!r}")
    for name in robots:
        if name not in BUILTIN_ROBOTS:
            raise ValueError(f"unknown robot {name!r}: the bench runs the built-in robots "
                             f"{', '.join(BUILTIN_ROBOTS)}")
    results = []
    for name in robots:
        robot = load_robot(name)
        warmup = max(1, iterations // 10)
        results += bench_controllers(robot, bench_holes(robot), controllers, iterations,
                                     warmup, plant=plant)
        if name == "sda10f_dual":
            results += bench_collisions(robot, controllers, iterations, warmup)
    return results


def bench_collisions(robot: Robot, controllers: Sequence[str], iterations: int,
                     warmup: int) -> list[StepTiming]:
    """The dual robot's arms close together (:func:`close_arms`), a hole on each, timed
    without collision avoidance (``sda10f_dual/close``) and with it
    (``sda10f_dual/collisions``: every self-collision pair, a few within the detection
    distance), over the same configurations."""
    collisions = CollisionAvoidance(robot)
    base = close_arms(robot, collisions)
    holes = bench_holes(robot, base)
    return [*bench_controllers(robot, holes, controllers, iterations, warmup,
                               label=f"{robot.name}/close", base=base),
            *bench_controllers(robot, holes, controllers, iterations, warmup,
                               label=f"{robot.name}/collisions", base=base,
                               collisions=collisions)]


def close_arms(robot: Robot, collisions: CollisionAvoidance, seed: int = 1,
               tries: int = 2000) -> np.ndarray:
    """A configuration near home (normal offsets of 0.4 rad, ``seed``) where the most pairs
    between the two arms lie within the detection distance, none closer than 1 cm: the
    first found with four such pairs, else the best of ``tries``."""
    model = robot.model
    data = model.createData()
    rng = np.random.default_rng(seed)
    best, best_count = robot.q_home.copy(), -1
    for _ in range(tries):
        q = pin.integrate(model, robot.q_home, rng.normal(scale=0.4, size=model.nv))
        pin.computeJointJacobians(model, data, q)
        rows = collisions.rows(model, data)
        if rows.size == 0 or rows.minimum_distance < 0.01:
            continue
        count = sum("left" in pair and "right" in pair for pair in rows.pairs)
        if count > best_count:
            best, best_count = q, count
        if count >= 4:
            break
    return best


def bench_twist(robot: Robot, holes: Sequence[Hole], base: np.ndarray | None = None) -> np.ndarray:
    """The stacked twist the bench asks for: :data:`BENCH_TWIST` for the first EE, and for
    the others what the least-norm ``qd`` with ``A qd = 0`` (the holes at home) and
    ``J_e1 qd = BENCH_TWIST`` gives them, so that the twists are consistent with the holes
    (two trocars on one torso cannot meet any pair, docs/design.md section 11.2), at
    ``base`` (default: home)."""
    base = robot.q_home if base is None else base
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, base)
    pin.updateFramePlacements(model, data)
    first, *others = robot.ee_frame_ids
    rows = np.vstack([_hole_rows(robot, holes, base),
                      pin.getFrameJacobian(model, data, first, pin.LOCAL)])
    goal = np.concatenate([np.zeros(sum(hole.dim for hole in holes)), BENCH_TWIST])
    qd = np.linalg.lstsq(rows, goal, rcond=None)[0]
    return np.concatenate([BENCH_TWIST, *(pin.getFrameJacobian(model, data, frame, pin.LOCAL) @ qd
                                          for frame in others)])


def _hole_rows(robot: Robot, holes: Sequence[Hole], base: np.ndarray | None = None) -> np.ndarray:
    """The holes' stacked rows ``A`` (``A qd = b``) at ``base`` (default: home)."""
    base = robot.q_home if base is None else base
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, base)
    pin.updateFramePlacements(model, data)
    return np.vstack([hole.rows(model, data, model.getFrameId(hole.link))[0] for hole in holes]
                     or [np.zeros((0, model.nv))])


def bench_holes(robot: Robot, base: np.ndarray | None = None) -> list[Hole]:
    """One hole on each of ``robot.constrained_links``, at the robot's
    :data:`DEFAULT_HOLE_DISTANCE` (0.1 m for a robot not listed) along it, at ``base``
    (default: home)."""
    distance = DEFAULT_HOLE_DISTANCE.get(robot.name, 0.1)
    base = robot.q_home if base is None else base
    return [Hole.on_link(robot, base, distance=distance, link=link)
            for link in robot.constrained_links]


def run_scaling(iterations: int = 300, controllers: Sequence[str] = SCALING_CONTROLLERS,
                dofs: Sequence[int] = SCALING_DOFS,
                holes: Sequence[int] = SCALING_HOLES) -> list[StepTiming]:
    """Generated chains: 1 hole on 8..64 DoF, then 1..8 holes on the 32-DoF chain."""
    results = []
    warmup = max(1, iterations // 10)
    for dof in dofs:
        robot = load_chain(dof)
        problem = [Hole.on_link(robot, robot.q_home, 0.05, link=hole_links(dof, 1)[0])]
        results += bench_controllers(robot, problem, controllers, iterations, warmup,
                                     label=f"chain{dof}")
    robot = load_chain(32)
    for count in holes:
        problem = [Hole.on_link(robot, robot.q_home, 0.05, link=link)
                   for link in hole_links(32, count)]
        results += bench_controllers(robot, problem, controllers, iterations, warmup,
                                     label=f"chain32/{count}holes")
    return results


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


def format_table(results: Sequence[StepTiming]) -> str:
    """One line per timing; ``qd dev``: the joint-velocity deviation from the problem's
    first controller (rad/s)."""
    ratios, daqp = mink_ratios(results), speedups(results, "qp:daqp")
    lines = [(f"{'problem':<24}{'dof':>4}{'rows':>5}  {'controller':<13}{'median us':>10}"
              f"{'p99 us':>9}{'max us':>10}{'x mink':>8}{'x daqp':>8}{'residual':>10}{'qd dev':>10}  "
              f"{'method':<12}statuses")]
    for r in results:
        ratio, daqp_ratio = ratios.get((r.robot, r.controller)), daqp.get((r.robot, r.controller))
        lines.append(
            f"{r.robot:<24}{r.dof:>4}{r.constraint_rows:>5}  {r.controller:<13}{r.median_us:>10.1f}"
            f"{r.p99_us:>9.1f}{r.max_us:>10.1f}{'' if ratio is None else f'{ratio:.1f}':>8}"
            f"{'' if daqp_ratio is None else f'{daqp_ratio:.1f}':>8}"
            f"{r.max_constraint_residual:>10.1e}{r.joint_velocity_deviation_max:>10.1e}  "
            f"{r.method:<12}{format_status_counts(r.status_counts)}")
    ticks = [r for r in results if r.plant_tick_median_us > 0]
    if ticks:
        lines += ["", f"{'problem':<20}  {'controller':<13}{'kinematic tick us':>18}"
                      f"{ticks[0].plant + ' tick us':>18}{'ratio':>8}"]
        lines += [f"{r.robot:<20}  {r.controller:<13}{r.kinematic_tick_median_us:>18.1f}"
                  f"{r.plant_tick_median_us:>18.1f}"
                  f"{r.plant_tick_median_us / r.kinematic_tick_median_us:>8.1f}" for r in ticks]
    return "\n".join(lines)


def write_json(results: Sequence[StepTiming], path: str) -> None:
    ratios = mink_ratios(results)
    daqp = speedups(results, "qp:daqp")
    rows = [{**asdict(r), "speedup_vs_mink": ratios.get((r.robot, r.controller)),
             "speedup_vs_qp_daqp": daqp.get((r.robot, r.controller))} for r in results]
    with open(path, "w", encoding="utf-8") as handle:
        json.dump(rows, handle, indent=2)
