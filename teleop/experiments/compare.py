"""Run controllers on the same plan and summarise what they did (``teleop compare``)."""

from __future__ import annotations

import collections
import csv
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from constraints import Constraint
from constraints.validation import as_number
from controllers import StepStatus
from controllers.step_message import StepMessage
from teleop.controller_specs import ROBOT, make_controller
from teleop.limits import MAX_DURATION_S, MAX_STEPS
from teleop.loop import RECORD_FIELDS, LoopConfig, MeasuredLater, StepRecord, TeleopLoop
from teleop.loop.plant import close_plant

from teleop.plants.imperfect import Imperfections
from teleop.plants.walls import has_wall

from .plan import Plan
from teleop.plants.choice import PlantChoice
from .variations import Variation
from .results import BODY_METRIC_KEYS, COLLISION_METRIC_KEYS, METRIC_KEYS, RunResult
from .solver_output import SolverOutputCapture

SCHEMA_VERSION = 9

#: the periods measured together after a run (:meth:`TeleopLoop.measure_all_later`: numpy's
#: cost per call shared by them; their kinematics a few hundred kB)
MEASURED_TOGETHER = 1000


def _steps(plan: Plan, config: LoopConfig, duration: float | None) -> int:
    """Control periods in ``duration`` s (default: the plan's): ``ValueError`` unless the
    duration is in (0, :data:`MAX_DURATION_S`] and the periods at most :data:`MAX_STEPS`."""
    duration = as_number(plan.duration if duration is None else duration, "duration",
                         positive=True, maximum=MAX_DURATION_S)
    steps = int(round(duration * config.rate))
    if steps > MAX_STEPS:
        raise ValueError(f"duration {duration:g} s at {config.rate:g} Hz is {steps} control "
                         f"periods, more than {MAX_STEPS}: lower the duration or the rate")
    return steps


def check_constraint_gain(plan: Plan, dt: float) -> None:
    """Refuse the plan's :attr:`~Plan.constraint_gain` where it is unstable at control
    period ``dt`` for one of the constraints the plan starts with (``ValueError`` naming
    ``constraint_gain``; docs/design.md 3.4); those its ``update`` adds are checked by the
    controller that takes them."""
    if plan.constraint_gain is None:
        return
    for constraint in plan.make_constraints():
        try:
            constraint.check_gain(dt)
        except ValueError as error:
            raise ValueError(f"constraint_gain: {error}") from None


def output_directory(out_dir: str | Path) -> Path:
    """``out_dir`` as a path where outputs can be written: an existing directory or none
    yet (a file, a device such as ``/dev/null``, raises ``ValueError``)."""
    if not isinstance(out_dir, (str, Path)) or not str(out_dir):
        raise ValueError(f"output directory must be a path, got {out_dir!r}")
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"output directory {str(out)!r} exists and is not a directory")
    return out


def _check_specs(specs: Sequence[str]) -> list[str]:
    """``specs`` as a list: at least one, none twice (results are keyed by spec)."""
    specs = list(specs)
    if not specs:
        raise ValueError("specs must name at least one controller")
    repeated = sorted({spec for spec in specs if specs.count(spec) > 1})
    if repeated:
        raise ValueError(f"specs lists {', '.join(map(repr, repeated))} twice")
    return specs


def run_plan(plan: Plan, spec: str, config: LoopConfig | None = None,
             duration: float | None = None,
             on_step: Callable[[int], None] | None = None,
             imperfections: Imperfections | None = None,
             plant: PlantChoice | None = None,
             acceleration_limits: bool = True,
             jerk_limit: float | None = None) -> RunResult:
    """Run one controller through ``plan`` and record every tick.

    ``imperfections`` (docs/design.md section 15.1) puts a robot that is not perfect under
    the loop; None or the default: the perfect robot. ``plant`` chooses the robot the loop
    drives (docs/design.md section 17); None: the kinematic one; the collision damper counts
    on its response time (:meth:`Plan.with_response_time`). ``acceleration_limits``:
    the controller keeps the robot's (docs/design.md 8.4; on by default, False: none);
    ``jerk_limit`` (rad/s^3 for every joint) a jerk limit too (8.5; None: none).
    """
    config = config or LoopConfig()
    steps = _steps(plan, config, duration)
    plant = plant or PlantChoice()
    plan = plan.with_response_time(plant.response_time)
    constraints = plan.make_constraints()
    plant.apply_wall(constraints)
    controller = _controller(spec, plan, constraints, config, acceleration_limits, jerk_limit)
    drive = _drive(plan, controller, constraints, config, steps, imperfections, on_step, plant)
    result = _collect(spec, drive, plan.robot.ee_frames)
    result.interface_limits = plant.settings.interface_limits if plant.physical else None
    if plan.collisions is not None:
        result.safety_distance = controller.collisions.safety_distance
    return result


@dataclass
class Drive:
    """What :func:`_drive` recorded: the steps, the first failures, each step's command
    and the names of the constraints with a wall (the holes' ports) at each step."""

    records: list[StepRecord] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    commands: list[np.ndarray] = field(default_factory=list)
    ports: list[tuple[str, ...]] = field(default_factory=list)


def _drive(plan: Plan, controller, constraints: list[Constraint], config: LoopConfig,
           steps: int, imperfections: Imperfections | None,
           on_step: Callable[[int], None] | None, plant: PlantChoice) -> Drive:
    """Tick ``controller`` (holding ``constraints``) through ``steps`` periods of ``plan``
    on the ``plant`` (every hole added on the way gets its wall), the measures on the true
    robot's kinematics (``imperfections.true_model``: with a calibration error, the same
    draw for every run), taken after the run where they can wait
    (:meth:`TeleopLoop.tick_measured_later`: the same records)."""
    imperfections = imperfections or Imperfections()
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=config,
                      plant=plant.make(plan.robot, config.dt, imperfections,
                                       plan.make_collisions()),
                      collisions=plan.make_collisions(),
                      true_model=imperfections.true_model(plan.robot.model))
    drive = Drive()
    records, failures = drive.records, drive.failures
    #: the periods, measured after the run (docs/design.md 5.1)
    periods: collections.deque[MeasuredLater] = collections.deque()
    edits_at_measure: list[list[Constraint]] = []

    def advance_geometry(now: float) -> None:
        """The geometry at the end of the tick, where the measures are taken."""
        changed = plan.update(now, loop.constraints, loop.q)
        if changed is not None:
            edits_at_measure.append(changed)

    try:
        for i in range(steps):
            t = i * config.dt
            changed = plan.update(t, constraints, loop.q)
            if changed is None and edits_at_measure:
                changed = edits_at_measure.pop()
            edits_at_measure.clear()
            if changed is not None:
                constraints = changed
                plant.apply_wall(constraints)
                loop.set_constraints(constraints)
            modes = plan.task_modes(t)
            if modes is not None and modes != loop.task_modes:
                loop.set_task_modes(modes)
            period = loop.tick_measured_later(plan.target(t + config.dt), advance_geometry)
            periods.append(period)
            drive.commands.append(loop.last_qd.copy())
            end = period.end
            drive.ports.append(tuple(name for name, constraint in zip(end.names, end.constraints)
                                     if has_wall(constraint)))
            if period.failed and len(failures) < 10:
                failures.append(f"t={period.t:.3f}s: {period.message}")
            if on_step is not None:
                on_step(i)
    finally:  # a robot on the wire gets its zeros when the run ends, not at exit
        if loop.plant is not None:
            close_plant(loop.plant)
    while periods:  # each batch let go once measured: the run's memory stays the records'
        batch = [periods.popleft() for _ in range(min(MEASURED_TOGETHER, len(periods)))]
        records.extend(loop.measure_all_later(batch))
    return drive


#: The distinct failure messages a run keeps; the rest are counted together.
MAX_FAILURE_MESSAGES = 20


def summarise_failures(records: Sequence[StepRecord]) -> list[dict]:
    """Every failed step of a run counted by its message: ``message``, ``count``,
    ``first_step`` (its index) and ``first_t_s``, the most frequent first; past
    :data:`MAX_FAILURE_MESSAGES` messages, one more entry counts the others' steps
    together ("N other messages")."""
    summary: dict[str, dict] = {}
    for index, record in enumerate(records):
        if not record.failed:
            continue
        entry = summary.setdefault(record.message, {
            "message": record.message, "count": 0, "first_step": index,
            "first_t_s": float(record.t)})
        entry["count"] += 1
    ranked = sorted(summary.values(), key=lambda entry: (-entry["count"], entry["first_step"]))
    kept, others = ranked[:MAX_FAILURE_MESSAGES], ranked[MAX_FAILURE_MESSAGES:]
    if others:
        first = min(others, key=lambda entry: entry["first_step"])
        kept.append({"message": f"{len(others)} other messages", "count": sum(
            entry["count"] for entry in others), "first_step": first["first_step"],
            "first_t_s": first["first_t_s"]})
    return kept


def _collect(spec: str, drive: Drive, ee_frames: Sequence[str]) -> RunResult:
    """The records as columns; constraint rows by label and constraints by name, NaN where
    one did not exist; the EE errors one column per EE; the plant's measures per port
    (NaN where the port did not exist) when the plant measured them."""
    records, failures = drive.records, drive.failures
    columns = {name: np.array([getattr(r, name) for r in records], dtype=float)
               for name in RECORD_FIELDS}
    labels = list(dict.fromkeys(label for r in records for label in r.constraint_velocity_labels))
    index = {label: j for j, label in enumerate(labels)}
    velocity = np.full((len(records), len(labels)), np.nan)
    drift = np.full((len(records), len(labels)), np.nan)
    for i, r in enumerate(records):
        where = [index[label] for label in r.constraint_velocity_labels]
        velocity[i, where] = r.constraint_velocity
        drift[i, where] = r.drift_velocity

    def vectors(name: str) -> np.ndarray:
        return np.array([getattr(r, name) for r in records]).reshape(-1, 3)

    names = list(dict.fromkeys(name for r in records for name in r.constraint_names))
    constraint_errors = {name: np.full(len(records), np.nan) for name in names}
    for i, r in enumerate(records):
        for name, error in zip(r.constraint_names, r.constraint_errors):
            constraint_errors[name][i] = error
    count = len(ee_frames)
    port_names = list(dict.fromkeys(name for ports in drive.ports for name in ports))
    measured = [r.plant for r in records if r.plant is not None and r.plant.physical]
    physical = len(measured) == len(records) and len(records) > 0
    port_forces = {name: np.full((len(records), 3), np.nan) for name in port_names}
    port_displacements = {name: np.full(len(records), np.nan) for name in port_names}
    port_springs = {name: np.full((len(records), 3), np.nan) for name in port_names}
    if physical:
        for i, (r, ports) in enumerate(zip(records, drive.ports)):
            for j, name in enumerate(ports):
                port_forces[name][i] = r.plant.port_forces[j]
                port_displacements[name][i] = r.plant.port_displacements[j]
                port_springs[name][i] = r.plant.port_spring_forces[j]

    return RunResult(
        controller=spec, columns=columns, constraint_velocity=velocity,
        constraint_velocity_labels=labels, drift_velocity=drift,
        operator_linear_velocity=vectors("operator_linear_velocity"),
        commanded_linear_velocity=vectors("commanded_linear_velocity"),
        actual_linear_velocity=vectors("actual_linear_velocity"),
        statuses=np.array([r.status for r in records], dtype=str),
        closest_pairs=np.array([r.closest_pair for r in records], dtype=object),
        ee_frames=tuple(ee_frames),
        ee_position_errors=np.array([r.ee_position_errors for r in records]).reshape(-1, count),
        ee_orientation_errors=np.array([r.ee_orientation_errors
                                        for r in records]).reshape(-1, count),
        constraint_errors=constraint_errors,
        failure_messages=failures,
        failure_summary=summarise_failures(records),
        status_counts=dict(collections.Counter(r.status for r in records)),
        controller_status_counts=dict(collections.Counter(r.controller_status for r in records)),
        supervisor_first_action=next((f"t={r.t:.3f}s: {r.message}" for r in records
                                      if r.supervisor_action != "none"), None),
        commanded_joint_velocity=np.array(drive.commands, dtype=float),
        actual_linear_velocities=np.array([r.actual_linear_velocities for r in records],
                                          dtype=float).reshape(-1, count, 3),
        port_names=port_names,
        port_forces=port_forces if physical else None,
        port_displacements=port_displacements if physical else None,
        torque_ratio=(np.array([m.torque_ratio for m in measured]) if physical else None),
        actuator_saturated=(np.array([m.saturated for m in measured]) if physical else None),
        contacts=(np.array([m.contacts for m in measured]) if physical else None),
        contact_depths=(np.array([m.contact_depth for m in measured]) if physical else None),
        port_spring_forces=port_springs if physical else None,
        interface_faults=(np.array([m.interface_fault is not None for m in measured])
                          if physical else None),
        interface_first_fault=next(((r.t, r.plant.interface_fault) for r in records
                                    if physical and r.plant.interface_fault is not None),
                                   None))


class ShadowedController:
    """The reference controller, with every other controller evaluated beside it
    (docs/design.md section 15.3).

    The loop sees only the reference: its command, its ``info``, its constraints. At each
    ``solve(q, twist)`` every shadow also solves at the same ``q`` and twist, and
    ``max_j |qd_shadow,j - qd_ref,j|`` is recorded (NaN for a step the reference refused).
    """

    def __init__(self, reference, shadows: dict[str, object]) -> None:
        self.reference = reference
        self.shadows = shadows
        self.deviations: dict[str, list[float]] = {spec: [] for spec in shadows}

    @property
    def info(self):
        return self.reference.info

    def step_outcome(self) -> tuple[StepStatus, StepMessage]:
        return self.reference.step_outcome()

    @property
    def constraints(self) -> list[Constraint]:
        return self.reference.constraints

    @property
    def constraint_frames(self) -> list[int]:
        return self.reference.constraint_frames

    def set_constraints(self, constraints: Sequence[Constraint]) -> None:
        for controller in (self.reference, *self.shadows.values()):
            controller.set_constraints(list(constraints))

    @property
    def twist_weight(self) -> np.ndarray:
        return self.reference.twist_weight

    @twist_weight.setter
    def twist_weight(self, twist_weight: np.ndarray) -> None:
        for controller in (self.reference, *self.shadows.values()):
            controller.twist_weight = twist_weight

    def solve(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        try:
            qd = self.reference.solve(q, twist)
        except ValueError:
            for series in self.deviations.values():
                series.append(math.nan)
            raise
        for spec, shadow in self.shadows.items():
            try:
                other = shadow.solve(q, twist)
            except ValueError:  # refused: the loop would hold still
                other = np.zeros_like(qd)
            self.deviations[spec].append(float(np.max(np.abs(other - qd))))
        return qd


def _controller(spec: str, plan: Plan, constraints: list[Constraint], config: LoopConfig,
                acceleration_limits: bool, jerk_limit: float | None = None):
    """A run's controller: simulated time, so iteration caps only, no deadline
    (docs/design.md 10.6); the robot's acceleration limits when asked for, and a jerk
    limit when given."""
    return make_controller(spec, plan.robot, constraints, dt=config.dt, time_budget=None,
                           acceleration_limit=ROBOT if acceleration_limits else None,
                           collisions=plan.make_collisions(), jerk_limit=jerk_limit)


def joint_velocity_agreement(plan: Plan, specs: Sequence[str], config: LoopConfig | None = None,
                             duration: float | None = None,
                             imperfections: Imperfections | None = None,
                             on_step: Callable[[int], None] | None = None,
                             plant: PlantChoice | None = None,
                             acceleration_limits: bool = True,
                             jerk_limit: float | None = None) -> dict[str, np.ndarray]:
    """Per step, ``max_j |qd_spec,j - qd_ref,j|`` (rad/s) of every spec against the first,
    all solved at the same ``q`` and twist along the first spec's closed-loop run (a shadow
    evaluation, docs/design.md section 15.3); zeros for the first spec itself."""
    specs = _check_specs(specs)
    config = config or LoopConfig()
    steps = _steps(plan, config, duration)
    plant = plant or PlantChoice()
    plan = plan.with_response_time(plant.response_time)
    constraints = plan.make_constraints()
    plant.apply_wall(constraints)
    reference = _controller(specs[0], plan, constraints, config, acceleration_limits,
                            jerk_limit)
    shadows = {spec: _controller(spec, plan, constraints, config, acceleration_limits,
                                 jerk_limit)
               for spec in specs[1:]}
    shadowed = ShadowedController(reference, shadows)
    _drive(plan, shadowed, constraints, config, steps, imperfections, on_step, plant)
    return {specs[0]: np.zeros(steps),
            **{spec: np.array(series) for spec, series in shadowed.deviations.items()}}


def compare(plan: Plan, specs: Sequence[str], config: LoopConfig | None = None,
            duration: float | None = None, progress: bool = True,
            imperfections: Imperfections | None = None,
            agreement: bool = True, plant: PlantChoice | None = None,
            acceleration_limits: bool = True,
            jerk_limit: float | None = None) -> dict[str, RunResult]:
    """Run every controller spec on the same plan (fresh constraints each), on the same
    ``plant`` (None: the kinematic one; each run builds its own), each controller with the
    robot's acceleration limits when ``acceleration_limits`` (and ``jerk_limit``, rad/s^3 on
    every joint, when given: docs/design.md 8.5) and with the plan's collision
    avoidance (``plan.collisions``, a fresh one per controller; the loop measures the
    minimum distance with one more, docs/design.md 18.6).

    With ``agreement`` and two or more specs, one more run of the first spec evaluates the
    others beside it (:func:`joint_velocity_agreement`). The solvers' console output and
    warnings are kept off the console, in each result's ``solver_messages`` (those of the
    agreement run repeat the runs' and are dropped). With ``progress``, standard error
    shows a progress bar with an estimate of the time left when it is a terminal, else one
    line per finished run.
    """
    config = config or LoopConfig()
    steps = _steps(plan, config, duration)
    specs = _check_specs(specs)
    (imperfections or Imperfections()).check_period(config.dt)
    check_constraint_gain(plan, config.dt)
    plant = plant or PlantChoice()
    plan = plan.with_response_time(plant.response_time)
    if plant.kind == "ros2" and len(specs) > 1:  # one robot: a second run starts elsewhere
        raise ValueError(f"the ros2 plant is one robot: run one controller on it "
                         f"(--controllers NAME), got {len(specs)}: {', '.join(specs)}")
    if plant.kind != "ros2":  # a ROS 2 robot is joined once (no idle writer on its topic)
        plant.make(plan.robot, config.dt, imperfections)  # fail fast: the model compiles
    for spec in specs:  # fail fast on a bad spec or damper, before minutes of simulation
        make_controller(spec, plan.robot, plan.make_constraints(), dt=config.dt,
                        collisions=plan.make_collisions(),
                        acceleration_limit=ROBOT if acceleration_limits else None,
                        jerk_limit=jerk_limit)
    agreement = agreement and len(specs) > 1
    runs = [*specs, *([f"joint velocities against {specs[0]}"] if agreement else [])]
    results = {}
    with SolverOutputCapture() as capture:
        report = RunProgress(plan.name, runs, steps, capture.console) if progress else None
        tick = report.step if report is not None else None
        try:
            for spec in specs:
                if report is not None:
                    report.start(spec)
                results[spec] = run_plan(plan, spec, config, duration, tick, imperfections,
                                         plant, acceleration_limits, jerk_limit)
                results[spec].solver_messages = capture.collect()
            if agreement:
                if report is not None:
                    report.start(runs[-1])
                deviations = joint_velocity_agreement(plan, specs, config, duration,
                                                      imperfections, tick, plant,
                                                      acceleration_limits, jerk_limit)
                capture.collect()
                for spec, deviation in deviations.items():
                    results[spec].joint_velocity_deviation = deviation
            if report is not None:
                report.finish()
        finally:
            if report is not None:
                report.close()
    return results


#: How many lines a run prints on its way when standard error is not a terminal (one
#: each tenth of its steps).
PROGRESS_LINES = 10


class RunProgress:
    """What :func:`compare` shows while it runs: on a terminal a tqdm bar over the current
    run's steps (named ``run i/n``, with its estimate of the run's time left), else,
    inside each run, a line at each tenth of its steps with the time left estimated from
    its pace so far, and one line per finished run (a log redirected to a file still
    shows a long pass going by)."""

    def __init__(self, name: str, runs: Sequence[str], steps: int, console) -> None:
        self.name, self.runs, self.steps, self.console = name, list(runs), steps, console
        self._run: str | None = None
        self._started = 0.0
        self._bar = None
        if console.isatty():
            from tqdm import tqdm

            self._bar = tqdm(total=steps, unit="step", desc=name, leave=False, file=console)

    def start(self, run: str) -> None:
        """``run`` begins (the one before it has finished)."""
        self.finish()
        if self._bar is not None and self._run is not None:
            self._bar.refresh()  # the run before it as it ended (refreshes are throttled)
        self._run, self._started = run, time.perf_counter()
        if self._bar is not None:
            self._bar.reset(total=self.steps)
            self._bar.set_description_str(
                f"{self.name}: {run} {self.runs.index(run) + 1}/{len(self.runs)}")

    def step(self, index: int) -> None:
        """Step ``index`` (from 0) of the current run has been taken."""
        if self._bar is not None:
            self._bar.update(1)
            return
        done = index + 1
        if done >= self.steps or done * PROGRESS_LINES % self.steps >= PROGRESS_LINES:
            return  # not the step that crosses a tenth (nor the last: finish says it)
        elapsed = time.perf_counter() - self._started
        left = elapsed * (self.steps - done) / done
        print(f"{self.name}: {self._run} {100 * done // self.steps}% ({done}/{self.steps} "
              f"steps, {elapsed:.1f} s, about {left:.0f} s left)", file=self.console, flush=True)

    def finish(self) -> None:
        """The current run has finished: its line (not on a terminal)."""
        if self._run is None or self._bar is not None:
            return
        done = self.runs.index(self._run) + 1
        print(f"{self.name}: {self._run} done ({done}/{len(self.runs)}, {self.steps} steps in "
              f"{time.perf_counter() - self._started:.1f} s)", file=self.console, flush=True)
        self._run = None

    def close(self) -> None:
        """Remove the bar (the runs are over, or stopped on an error)."""
        if self._bar is not None:
            self._bar.close()


def metrics_document(plan: Plan, results: dict[str, RunResult], config: LoopConfig,
                     duration: float, imperfections: Imperfections | None = None,
                     plant: PlantChoice | None = None,
                     acceleration_limits: bool = True,
                     variation: Variation | None = None,
                     jerk_limit: float | None = None) -> dict:
    """The metrics.json document (schema: ``teleop/experiments/metrics.schema.json``);
    ``variation`` is what :meth:`Variation.apply` made ``plan`` of (None: nothing), the
    constraint gain the plan's (:meth:`Plan.with_constraint_gain`)."""
    first = next(iter(results.values()), None)
    reference = (next(iter(results)) if first is not None
                 and first.joint_velocity_deviation is not None else None)
    return {
        "schema_version": SCHEMA_VERSION,
        "scenario": plan.name,
        "description": plan.description,
        "robot": plan.robot.name,
        "ee_frames": list(plan.robot.ee_frames),
        "rate_hz": config.rate,
        "duration_s": duration,
        "steps": int(round(duration * config.rate)),
        "imperfections": (imperfections or Imperfections()).to_dict(),
        "plant": (plant or PlantChoice()).to_dict(),
        "acceleration_limits": bool(acceleration_limits),
        "jerk_limit": jerk_limit,
        "variation": (variation or Variation()).to_dict(),
        "kp": config.kp,
        "supervisor": config.supervisor.to_dict(),
        "constraint_gain": plan.constraint_gain,
        "collisions": plan.with_response_time(
            (plant or PlantChoice()).response_time).collisions,
        "joint_velocity_reference": reference,
        "controllers": {spec: result.metrics() for spec, result in results.items()},
    }


def write_outputs(plan: Plan, results: dict[str, RunResult], config: LoopConfig,
                  duration: float, out_dir: str | Path, plots: bool = True,
                  imperfections: Imperfections | None = None,
                  plant: PlantChoice | None = None,
                  acceleration_limits: bool = True,
                  variation: Variation | None = None,
                  jerk_limit: float | None = None) -> list[Path]:
    """metrics.json, metrics.csv and, with ``plots``, the PNG plots and report.html into
    ``out_dir`` (``variation``: :func:`metrics_document`); returns the paths."""
    out = output_directory(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ValueError(f"cannot create output directory {str(out)!r}: {error.strerror}") from None
    document = metrics_document(plan, results, config, duration, imperfections, plant,
                                acceleration_limits, variation, jerk_limit)
    paths = [out / "metrics.json", out / "metrics.csv"]
    paths[0].write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    with paths[1].open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        keys = (*METRIC_KEYS, *COLLISION_METRIC_KEYS, *BODY_METRIC_KEYS)
        writer.writerow(["controller", *keys])
        for spec, metrics in document["controllers"].items():
            writer.writerow([spec, *("" if metrics[key] is None else metrics[key]
                                     for key in keys)])
    if plots:
        from .plots import write_plots
        from .report import write_report

        figures = write_plots(plan, results, out, plant or PlantChoice())
        paths += [figure.path for figure in figures]
        paths.append(write_report(document, figures, out / "report.html"))
    return paths
