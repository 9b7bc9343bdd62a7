"""``teleop compare`` on a contact scenario (docs/design.md section 21.4): every controller
through the same experiment with a tool-frame force law on the MuJoCo plant, the force
measures of each in one table and one ``contact_metrics.json``.

A contact scenario is not a :class:`~teleop.experiments.plan.Plan`: the force law sits
between the operator's twist and the controller and reads the plant's force/torque
sensor, so each registers the function that runs it (:data:`CONTACT_SCENARIOS`).
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleop.plants.choice import PlantChoice

from .compare import output_directory
from . import palpation, retraction
from .contact_run import ContactMeasures, ContactTask, run_contact

#: The version of ``contact_metrics.json``'s layout.
CONTACT_SCHEMA_VERSION = 2

#: The measures of a contact run, with their units and the table's headings.
CONTACT_MEASURES = (
    ("force_error_rms", "N", "force err RMS"), ("force_error_max", "N", "force err max"),
    ("contact_lost", "periods", "contact lost"), ("port_force_max", "N", "port force max"),
    ("hole_error_max", "m", "hole err max"), ("ee_error_max", "m", "EE err max"),
    ("jerk_max", "rad/s^3", "jerk max"), ("sensed_vs_true_max", "N", "sensed-true max"),
    ("interface_faults", "periods", "interface faults"))


@dataclass(frozen=True)
class ContactScenario:
    """A contact scenario: one line for humans and its task
    (:func:`~teleop.experiments.contact_run.run_contact` runs it)."""

    description: str
    task: ContactTask


#: The contact scenarios by name (``teleop compare --scenario NAME --plant mujoco``).
CONTACT_SCENARIOS: dict[str, ContactScenario] = {
    "palpation": ContactScenario(palpation.DESCRIPTION, palpation.PALPATION),
    "retraction": ContactScenario(retraction.DESCRIPTION, retraction.RETRACTION),
    "retraction-y": ContactScenario(retraction.DESCRIPTION_Y, retraction.RETRACTION_Y),
}


def refuse_contact_scenario(name: str, command: str) -> None:
    """``ValueError`` when ``name`` is a contact scenario and ``command`` (``teleop record``,
    ``teleop sweep``) runs plans: a contact run's force law reads the plant's sensor every
    period, which neither a recording's targets nor a sweep's cells carry, so only
    ``teleop compare`` runs it."""
    if name in CONTACT_SCENARIOS:
        raise ValueError(f"{name} is a contact scenario (a force law between the operator and "
                         f"the controller): {command} runs the plan scenarios only; run it with "
                         f"teleop compare --scenario {name} --plant mujoco")


def compare_contact(name: str, specs: Sequence[str], plant: PlantChoice, rate: float = 1000.0,
                    duration: float | None = None, sensor_noise: float = 0.0, seed: int = 0,
                    acceleration_limits: bool = True, jerk_limit: float | None = None,
                    force_filter: float | None = None,
                    progress: bool = True) -> tuple[dict, dict[str, ContactMeasures]]:
    """Run every controller of ``specs`` through contact scenario ``name`` on ``plant``
    (the mujoco plant: ``ValueError`` naming the plant otherwise), the same sensor noise
    and seed for each; returns the ``contact_metrics.json`` document and the measures."""
    if name not in CONTACT_SCENARIOS:
        raise ValueError(f"unknown contact scenario {name!r}; contact scenarios: "
                         f"{', '.join(CONTACT_SCENARIOS)}")
    scenario = CONTACT_SCENARIOS[name]
    if plant.kind != "mujoco":
        raise ValueError(f"scenario {name!r} needs --plant mujoco: the {plant.kind} plant has "
                         f"no force/torque sensor at the tool (docs/design.md 21.2)")
    specs = list(specs)
    if not specs or len(set(specs)) != len(specs):
        raise ValueError(f"controllers must be at least one, none twice, got {specs!r}")
    dt = 1.0 / rate
    duration = scenario.task.duration if duration is None else duration
    results = {}
    for spec in specs:
        started = time.perf_counter()
        results[spec] = run_contact(scenario.task, spec, dt=dt, duration=duration,
                                    sensor_noise=sensor_noise, seed=seed, plant=plant,
                                    acceleration_limits=acceleration_limits,
                                    jerk_limit=jerk_limit, force_filter=force_filter)
        if progress:
            print(f"{name}: {spec} done ({time.perf_counter() - started:.1f} s)",
                  file=sys.stderr, flush=True)
    document = {
        "schema_version": CONTACT_SCHEMA_VERSION, "scenario": name,
        "description": scenario.description, "rate_hz": rate, "duration_s": duration,
        "setpoint_n": scenario.task.setpoint, "sensor_noise_n": sensor_noise, "seed": seed,
        "force_filter_hz": force_filter, "plant": plant.to_dict(),
        "acceleration_limits": acceleration_limits, "jerk_limit": jerk_limit,
        "units": {key: unit for key, unit, _ in CONTACT_MEASURES},
        "controllers": {spec: {key: _number(getattr(measures, key))
                               for key, _, _ in CONTACT_MEASURES}
                        for spec, measures in results.items()},
    }
    return document, results


def _number(value: float | int | None) -> float | int | None:
    if value is None:  # not measured (the interface's faults with its check off)
        return None
    return int(value) if isinstance(value, (int, np.integer)) else float(value)


def format_contact_table(document: dict) -> str:
    """The measures of every controller, one row each (forces in N, errors in mm; ``-``:
    not measured)."""
    headings = ["controller", *(heading for _, _, heading in CONTACT_MEASURES)]
    rows = []
    for spec, measures in document["controllers"].items():
        row = [spec]
        for key, unit, _ in CONTACT_MEASURES:
            value = measures[key]
            row.append("-" if value is None else f"{value:d}" if unit == "periods"
                       else f"{1e3 * value:.3f} mm"
                       if unit == "m" else f"{value:.3g}" if unit == "rad/s^3"
                       else f"{value:.4f}")
        rows.append(row)
    widths = [max(len(cell) for cell in column) for column in zip(headings, *rows)]
    return "\n".join("  ".join(cell.ljust(width) for cell, width in zip(line, widths)).rstrip()
                     for line in (headings, *rows))


def write_contact_outputs(document: dict, results: dict[str, ContactMeasures],
                          out_dir: str | Path, plots: bool = True) -> list[Path]:
    """``contact_metrics.json`` and, with ``plots``, ``contact_force.png`` (every
    controller's true contact force over time, the setpoint dashed) into ``out_dir``."""
    out = output_directory(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ValueError(f"cannot create output directory {str(out)!r}: {error.strerror}") from None
    paths = [out / "contact_metrics.json"]
    paths[0].write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    if plots:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        figure, axes = plt.subplots(figsize=(7.0, 3.2))
        for spec, measures in results.items():
            axes.plot(measures.times, measures.forces, label=spec, linewidth=1.0)
        axes.axhline(document["setpoint_n"], color="black", linestyle="--", linewidth=0.8,
                     label="setpoint")
        axes.set_xlabel("t (s)")
        axes.set_ylabel("contact force (N)")
        axes.set_title(f"{document['scenario']}: the tissue's force on the tip")
        axes.legend(fontsize=8)
        figure.tight_layout()
        paths.append(out / "contact_force.png")
        figure.savefig(paths[-1], dpi=110)
        plt.close(figure)
    return paths
