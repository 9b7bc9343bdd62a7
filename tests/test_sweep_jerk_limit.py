"""A sweep cell's ``jerk_limit`` (issue 32 item 2, docs/design.md 8.5): the field reaches the
controller of the cell's run, its key leaves the field out when absent (old databases keep
their keys), the sweep's command line takes it, and a cell without the acceleration limits
is refused by name. The jerk is measured in the test from the run's commands."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from teleop.cli.sweep import add_arguments, options_document
from teleop.experiments.compare import run_plan
from teleop.experiments.sweep.cell import build_run, run_cell
from teleop.experiments.sweep.spec import build_spec

BASE = {"scenarios": ["fast-lateral"], "controllers": ["cjm"], "seeds": 1, "duration": 0.5}
LIMIT = 1000.0


def largest_jerk(inputs: dict) -> float:
    """The largest |qd_k - 2 qd_k-1 + qd_k-2| / dt^2 of the cell's run."""
    run = build_run(inputs)
    result = run_plan(run.plan, inputs["controller"], run.config, run.duration,
                      imperfections=run.imperfections, plant=run.plant,
                      acceleration_limits=run.acceleration_limits, jerk_limit=run.jerk_limit)
    commands = result.commanded_joint_velocity
    return float(np.abs(np.diff(commands, n=2, axis=0)).max()) / run.config.dt**2


def test_a_cell_with_a_jerk_limit_keeps_it_and_one_without_does_not():
    free, = build_spec(BASE).cells()
    limited, = build_spec({**BASE, "jerk_limit": LIMIT}).cells()
    assert "jerk_limit" not in free.inputs and free.key != limited.key
    assert largest_jerk(limited.inputs) <= LIMIT * (1 + 1e-9)
    assert largest_jerk(free.inputs) > 2 * LIMIT
    rms = [run_cell(cell.inputs, 120.0)["metrics"]["joint_jerk_rms_radps3"]
           for cell in (free, limited)]
    assert rms[1] < rms[0]


def test_the_sweep_command_line_takes_jerk_limits_as_a_grid_axis():
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["--out", "x", "--scenarios", "fast-lateral",
                              "--jerk-limit", "1000,5000"])
    document = options_document(args)
    assert document["jerk_limit"] == [1000.0, 5000.0]
    cells = build_spec({**BASE, **{k: v for k, v in document.items() if k != "scenarios"}}).cells()
    assert sorted(cell.inputs["jerk_limit"] for cell in cells) == [1000.0, 5000.0]


def test_bad_jerk_limits_are_refused_by_name():
    with pytest.raises(ValueError, match="jerk_limit must be"):
        build_spec({**BASE, "jerk_limit": 0})
    cell, = build_spec({**BASE, "jerk_limit": LIMIT, "acceleration_limits": False}).cells()
    with pytest.raises(ValueError, match="jerk_limit needs the acceleration limits"):
        build_run(cell.inputs)
    outcome = run_cell(cell.inputs, 60.0)
    assert outcome["status"] == "failed" and "acceleration limits" in outcome["reason"]
