"""One cell of a sweep: a ``compare`` run of one controller, from its inputs alone
(docs/sweep.md).

:func:`run_cell` is what a worker runs, in a process of its own: it builds the scenario,
the variation, the imperfections, the plant and the loop settings from the cell's inputs,
runs the controller through the closed loop and returns the outcome (a plain, picklable
mapping). The cell stops itself at its time limit, checked every control period; any
error of the run is the cell's failed outcome, never the sweep's.
"""

from __future__ import annotations

import os
import shlex
import socket
import time
from dataclasses import dataclass
from typing import Any, Mapping

from .spec import FIELDS_BY_NAME, cell_value, scenario_robot

#: A cell's outcomes.
DONE, FAILED = "done", "failed"


class TimeLimitExceeded(Exception):
    """A cell ran past its wall-clock limit (raised from the loop's step callback)."""


@dataclass(frozen=True)
class CellRun:
    """What a cell's inputs build: the plan (scenario and variation), the loop settings,
    the imperfections, the plant, the duration, whether the acceleration limits are kept,
    the jerk limit (rad/s^3, or None)."""

    plan: Any
    config: Any
    imperfections: Any
    plant: Any
    duration: float
    acceleration_limits: bool
    jerk_limit: float | None


def build_run(inputs: Mapping[str, Any]) -> CellRun:
    """The objects of a cell's run (``ValueError`` for inputs they refuse)."""
    from teleop.experiments.scenarios import load_scenario
    from teleop.experiments.variations import Variation
    from teleop.loop import LoopConfig
    from teleop.plants import PlantSettings
    from teleop.plants.choice import PlantChoice
    from teleop.plants.imperfect import Imperfections

    def value(name: str) -> Any:
        return cell_value(inputs, name)

    seed = value("seed")
    plan = load_scenario(value("scenario"), scenario_robot(value("scenario"), value("robot")))
    plan = Variation(value("trocar_shift"), value("path_amplitude"), seed).apply(plan)
    if value("constraint_gain") is not None:
        plan = plan.with_constraint_gain(value("constraint_gain"))
    config = LoopConfig(rate=value("rate"), kp=value("kp"))
    imperfections = Imperfections(
        value("encoder_noise"), value("latency"), value("joint_time_constant"), seed,
        calibration_position_std=value("calibration_error_mm") * 1e-3,
        calibration_rotation_std=value("calibration_error_mrad") * 1e-3)
    physics = (PlantSettings(payload=value("payload")) if value("plant") == "mujoco"
               else PlantSettings())
    plant = PlantChoice(value("plant"), physics)
    duration = value("duration") or plan.duration
    if value("jerk_limit") is not None and not value("acceleration_limits"):
        raise ValueError("jerk_limit needs the acceleration limits (docs/design.md 8.5)")
    return CellRun(plan, config, imperfections, plant, duration, value("acceleration_limits"),
                   value("jerk_limit"))


def run_cell(inputs: Mapping[str, Any], time_limit: float) -> dict[str, Any]:
    """Run one cell; its outcome: ``status`` (:data:`DONE` or :data:`FAILED`), ``reason``
    (why it failed, else None), ``metrics`` (``RunResult.metrics()``, the same as the
    controller's entry in ``teleop compare``'s metrics.json), ``elapsed_s``, ``worker``
    (host:pid) and ``version``."""
    from teleop.experiments.compare import run_plan
    from teleop.experiments.solver_output import SolverOutputCapture

    started = time.monotonic()
    outcome: dict[str, Any] = {"status": FAILED, "reason": None, "metrics": None,
                               "worker": f"{socket.gethostname()}:{os.getpid()}",
                               "version": package_version()}
    try:
        run = build_run(inputs)
        deadline = started + time_limit
        dt = run.config.dt

        def check_time(step: int) -> None:
            if time.monotonic() > deadline:
                raise TimeLimitExceeded(f"time limit {time_limit:g} s exceeded at "
                                        f"t={step * dt:.1f} s of {run.duration:g} s")

        with SolverOutputCapture() as capture:
            result = run_plan(run.plan, inputs["controller"], run.config, run.duration,
                              check_time, run.imperfections, run.plant, run.acceleration_limits,
                              run.jerk_limit)
            result.solver_messages = capture.collect()
        outcome.update(status=DONE, metrics=result.metrics())
    except TimeLimitExceeded as error:
        outcome["reason"] = str(error)
    except Exception as error:  # the cell's own failure is its outcome, the sweep goes on
        outcome["reason"] = f"{type(error).__name__}: {' '.join(str(error).split())}"
    outcome["elapsed_s"] = time.monotonic() - started
    return outcome


def package_version() -> str:
    from importlib import metadata

    try:
        return metadata.version("cjm-teleop")
    except metadata.PackageNotFoundError:
        return "unknown"


def compare_command(inputs: Mapping[str, Any], out: str = "out") -> str:
    """The ``teleop compare`` command that runs the cell again, alone (its metrics are the
    cell's, the step times aside)."""
    words = ["teleop", "compare"]
    for name, value in inputs.items():
        if name in ("calibration_error_mm", "calibration_error_mrad"):
            continue
        if name == "acceleration_limits":
            words += [] if value else ["--no-acceleration-limits"]
            continue
        if name == "robot":
            words += _robot_words(value)
            continue
        words += [FIELDS_BY_NAME[name].option, _shown(value)]
    if "calibration_error_mm" in inputs or "calibration_error_mrad" in inputs:
        words += ["--calibration-error", f"{_shown(cell_value(inputs, 'calibration_error_mm'))},"
                  f"{_shown(cell_value(inputs, 'calibration_error_mrad'))}"]
    words += ["--out", out]
    return shlex.join(words)


def _robot_words(robot: Mapping[str, Any]) -> list[str]:
    """A cell's robot table as ``teleop compare``'s robot options."""
    words: list[str] = []
    for key, value in robot.items():
        option = f"--{key.replace('_', '-')}"
        if key == "link_axis":
            words += [option, *(_shown(v) for v in value)]
        elif isinstance(value, list):
            words += [f"{option}={','.join(_shown(v) for v in value)}"]
        else:
            words += [option, value]
    return words


def _shown(value: Any) -> str:
    return repr(value) if isinstance(value, float) else str(value)
