"""Does the loop's status describe the robot? (docs/design.md 5.2, issue 32 item 4)

    python docs/audit_supervisor.py PLANT [--no-acceleration-limits] [--encoder-noise RAD]
                                    [--scenarios A,B] [--controllers cjm,qp:proxqp,mink:daqp]

One JSON line per scenario x controller on PLANT (``kinematic`` or ``mujoco``), the whole
scenario at 1 kHz with the default supervisor:

* ``ok_above_tolerance``: steps ``ok`` whose constraint error measured at the sensed
  configuration is above 0.1 mm (the supervisor's promise: 0);
* ``above_1mm_or_1N``, ``unflagged``: steps whose true constraint error (end of period,
  an equality's error or a barrier's penetration) is above 1 mm or whose port force is
  above 1 N, and those of them recorded ``ok`` (the issue's target: 0);
* the largest true and measured errors, the port force, the supervisor's scaled and held
  steps.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from teleop.experiments.compare import run_plan
from teleop.experiments.scenarios import SCENARIOS, load_scenario
from teleop.plants.choice import PlantChoice
from teleop.plants.imperfect import Imperfections

#: the issue's bars: an error (m) and a port force (N) that must never be ``ok``
ERROR_BAR, FORCE_BAR = 1e-3, 1.0


def audit(scenario: str, spec: str, plant: PlantChoice, acceleration_limits: bool,
          encoder_noise: float) -> dict:
    """One run's counts (the module's docstring)."""
    start = time.perf_counter()
    result = run_plan(load_scenario(scenario), spec, plant=plant,
                      acceleration_limits=acceleration_limits,
                      imperfections=Imperfections(encoder_noise=encoder_noise))
    columns, statuses = result.columns, result.statuses
    measured = columns["measured_constraint_error"]
    true_error = np.maximum(columns["constraint_error"], columns["barrier_penetration"])
    forces = result.port_force_magnitudes()
    force = (np.nanmax(np.column_stack(list(forces.values())), axis=1) if forces
             else np.zeros(len(statuses)))
    beyond = (true_error > ERROR_BAR) | (force > FORCE_BAR)
    ok = statuses == "ok"
    metrics = result.metrics()
    return {
        "scenario": scenario, "controller": spec, "plant": plant.kind,
        "acceleration_limits": acceleration_limits, "encoder_noise": encoder_noise,
        "ok_above_tolerance": int(np.sum(ok & (measured > 1e-4))),
        "above_1mm_or_1N": int(np.sum(beyond)), "unflagged": int(np.sum(ok & beyond)),
        "ok_steps": int(np.sum(ok)),
        "controller_ok_steps": metrics["controller_status_counts"].get("ok", 0),
        "error_max_mm": 1e3 * float(np.max(true_error)),
        "measured_error_max_mm": 1e3 * float(np.max(measured)),
        "port_force_max_n": metrics["port_force_max_n"],
        "scaled_steps": metrics["supervisor"]["scaled_steps"],
        "held_steps": metrics["supervisor"]["held_steps"],
        "failed_steps": metrics["failed_steps"],
        "seconds": round(time.perf_counter() - start, 1),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("plant", choices=("kinematic", "mujoco"))
    parser.add_argument("--acceleration-limits", action=argparse.BooleanOptionalAction,
                        default=True, help="the robots' acceleration limits, on as in every "
                        "command of the project (default: on)")
    parser.add_argument("--encoder-noise", type=float, default=0.0)
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--controllers", default="cjm,qp:proxqp,mink:daqp")
    args = parser.parse_args()
    for scenario in args.scenarios.split(","):
        for spec in args.controllers.split(","):
            print(json.dumps(audit(scenario, spec, PlantChoice(args.plant),
                                   args.acceleration_limits, args.encoder_noise)), flush=True)


if __name__ == "__main__":
    main()
