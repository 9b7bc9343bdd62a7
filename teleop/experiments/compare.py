"""Run controllers on the same plan and summarise what they did (``teleop compare``)."""

from __future__ import annotations

import collections
import csv
import json
import math
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from constraints import Constraint
from teleop.controller_specs import make_controller
from teleop.loop import RECORD_FIELDS, LoopConfig, StepRecord, TeleopLoop

from .plan import Plan
from .results import METRIC_KEYS, RunResult

SCHEMA_VERSION = 1


def run_plan(plan: Plan, spec: str, config: LoopConfig | None = None,
             duration: float | None = None,
             on_step: Callable[[int], None] | None = None) -> RunResult:
    """Run one controller through ``plan`` and record every tick."""
    config = config or LoopConfig()
    duration = plan.duration if duration is None else float(duration)
    if not math.isfinite(duration) or duration <= 0:
        raise ValueError(f"duration must be > 0 s, got {duration}")
    constraints = plan.make_constraints()
    controller = make_controller(spec, plan.robot, constraints, dt=config.dt)
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=config)
    steps = int(round(duration * config.rate))
    records: list[StepRecord] = []
    failures: list[str] = []
    edits_at_measure: list[list[Constraint]] = []

    def advance_geometry(now: float) -> None:
        """The geometry at the end of the tick, where the measures are taken."""
        changed = plan.update(now, loop.constraints, loop.q)
        if changed is not None:
            edits_at_measure.append(changed)

    for i in range(steps):
        t = i * config.dt
        changed = plan.update(t, constraints, loop.q)
        if changed is None and edits_at_measure:
            changed = edits_at_measure.pop()
        edits_at_measure.clear()
        if changed is not None:
            constraints = changed
            loop.set_constraints(constraints)
        record = loop.tick(plan.target(t + config.dt), advance_geometry)
        records.append(record)
        if record.failed and len(failures) < 10:
            failures.append(f"t={record.t:.3f}s: {record.message}")
        if on_step is not None:
            on_step(i)
    return _collect(spec, records, failures)


def _collect(spec: str, records: Sequence[StepRecord], failures: list[str]) -> RunResult:
    columns = {name: np.array([getattr(r, name) for r in records], dtype=float)
               for name in RECORD_FIELDS}
    width = max((len(r.constraint_velocity) for r in records), default=0)
    velocity = np.zeros((len(records), width))
    for i, r in enumerate(records):
        velocity[i, :len(r.constraint_velocity)] = r.constraint_velocity
    return RunResult(
        controller=spec, columns=columns, constraint_velocity=velocity,
        desired_linear_velocity=np.array([r.desired_linear_velocity for r in records]).reshape(-1, 3),
        actual_linear_velocity=np.array([r.actual_linear_velocity for r in records]).reshape(-1, 3),
        failure_messages=failures,
        status_counts=dict(collections.Counter(r.status for r in records)))


def compare(plan: Plan, specs: Sequence[str], config: LoopConfig | None = None,
            duration: float | None = None, progress: bool = True) -> dict[str, RunResult]:
    """Run every controller spec on the same plan (fresh constraints each)."""
    config = config or LoopConfig()
    duration = plan.duration if duration is None else duration
    steps = int(round(duration * config.rate))
    for spec in specs:  # fail fast on a bad spec, before minutes of simulation
        make_controller(spec, plan.robot, plan.make_constraints(), dt=config.dt)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=steps * len(specs), unit="step", desc=plan.name, leave=False,
                   disable=None)  # None: no bar when stderr is not a terminal
    results = {}
    try:
        for spec in specs:
            if bar is not None:
                bar.set_postfix_str(spec)
            results[spec] = run_plan(plan, spec, config, duration,
                                     on_step=(lambda i: bar.update(1)) if bar else None)
    finally:
        if bar is not None:
            bar.close()
    return results


def metrics_document(plan: Plan, results: dict[str, RunResult], config: LoopConfig,
                     duration: float) -> dict:
    """The metrics.json document (schema: ``teleop/metrics.schema.json``)."""
    return {
        "schema_version": SCHEMA_VERSION,
        "scenario": plan.name,
        "description": plan.description,
        "robot": plan.robot.name,
        "rate_hz": config.rate,
        "duration_s": duration,
        "steps": int(round(duration * config.rate)),
        "controllers": {spec: result.metrics() for spec, result in results.items()},
    }


def write_outputs(plan: Plan, results: dict[str, RunResult], config: LoopConfig,
                  duration: float, out_dir: str | Path, plots: bool = True) -> list[Path]:
    """metrics.json, metrics.csv and the PNG plots into ``out_dir``; returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    document = metrics_document(plan, results, config, duration)
    paths = [out / "metrics.json", out / "metrics.csv"]
    paths[0].write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    with paths[1].open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(["controller", *METRIC_KEYS])
        for spec, metrics in document["controllers"].items():
            writer.writerow([spec, *(metrics[key] for key in METRIC_KEYS)])
    if plots:
        from .plots import write_plots

        paths += write_plots(plan, results, out)
    return paths


def format_table(document: dict) -> str:
    """A short table of the headline numbers for the terminal and the README."""
    header = ("| controller | constraint err max (m) | RMS (m) | residual max (m/s) | "
              "EE pos RMS (mm) | EE ori RMS (mrad) | limit viol (rad) | failed | "
              "step median/p99 (us) | steps by status |")
    lines = [header, "|" + "---|" * 10]
    for spec, m in document["controllers"].items():
        lines.append(
            f"| {spec} | {m['constraint_error_max_m']:.1e} | {m['constraint_error_rms_m']:.1e} | "
            f"{m['constraint_velocity_residual_max_mps']:.1e} | "
            f"{1e3 * m['ee_position_error_rms_m']:.3f} | "
            f"{1e3 * m['ee_orientation_error_rms_rad']:.3f} | "
            f"{m['joint_limit_violation_max_rad']:.3f} | {m['failed_steps']} | "
            f"{m['step_time_median_us']:.0f} / {m['step_time_p99_us']:.0f} | "
            f"{format_status_counts(m['status_counts'])} |")
    return "\n".join(lines)


def format_status_counts(counts: dict[str, int]) -> str:
    """``ok 9990, scaled 10``: the statuses in order of severity, zeros left out."""
    order = ("ok", "scaled", "least_squares", "constraint_degraded", "failed")
    return ", ".join(f"{status} {counts[status]}" for status in order if counts.get(status))
