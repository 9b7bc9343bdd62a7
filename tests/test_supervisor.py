"""The loop watches the robot (docs/design.md 5.2): each constraint's error measured at the
sensed configuration makes a step ``ok`` only within tolerance, and the supervisor scales
the operator's twist between its warning and hold levels, holds it beyond, and says so in
the records, metrics.json and the command line."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from importlib.resources import files

import jsonschema
import numpy as np
import pytest

from teleop.controller_specs import make_controller
from teleop.experiments.compare import run_plan
from teleop.experiments.plan import Plan
from teleop.experiments.scenarios import load_scenario
from teleop.loop import LoopConfig, TeleopLoop
from teleop.loop.supervisor import Supervision, SupervisorConfig, ramp
from teleop.plants.choice import PlantChoice
from teleop.plants.imperfect import Imperfections

SCHEMA = json.loads(files("teleop.experiments").joinpath("metrics.schema.json").read_text())
MUJOCO = PlantChoice("mujoco")
DEFAULT = SupervisorConfig()


def faster(plan: Plan, factor: float) -> Plan:
    """``plan`` with an operator ``factor`` times as fast (the same path, in less time)."""
    return dataclasses.replace(plan, target=lambda t: plan.target(factor * t),
                               duration=plan.duration / factor)


def check_supervised(result, config: SupervisorConfig = DEFAULT) -> None:
    """Every step of ``result``: never ``ok`` beyond tolerance; the scale at most the ramp
    of the measured error and port force, zero from the hold level (1 throughout when the
    supervisor only measures)."""
    c = result.columns
    measured, force = c["measured_constraint_error"], c["measured_port_force"]
    scale, status = c["supervisor_scale"], result.statuses
    beyond = (measured > config.tolerance) | (np.nan_to_num(force) > config.force_tolerance)
    assert not np.any((status == "ok") & beyond)
    assert np.all(status[beyond] != "ok")
    for i in np.flatnonzero(beyond):
        assert status[i] in ("constraint_degraded", "failed")
    if not config.acting:
        assert np.all(scale == 1.0)
        return
    wanted = np.minimum([ramp(e, config.error_warn, config.error_hold) for e in measured],
                        [ramp(f, config.force_warn, config.force_hold) for f in force])
    assert np.all(scale <= wanted + 1e-15)
    held = (measured >= config.error_hold) | (np.nan_to_num(force) >= config.force_hold)
    assert np.all(scale[held] == 0.0)


def test_the_thresholds_name_the_field():
    for kwargs, field in [({"tolerance": 0.0}, "tolerance"), ({"error_warn": -1e-3}, "error_warn"),
                          ({"error_hold": float("nan")}, "error_hold"),
                          ({"force_warn": "1"}, "force_warn"), ({"force_hold": True}, "force_hold"),
                          ({"release_time": -0.1}, "release_time"),
                          ({"error_warn": 2e-3, "error_hold": 2e-3}, "error_warn"),
                          ({"force_warn": 3.0}, "force_warn"), ({"acting": 1}, "acting")]:
        with pytest.raises(ValueError, match=field):
            SupervisorConfig(**kwargs)
    with pytest.raises(ValueError, match="supervisor must be a SupervisorConfig"):
        LoopConfig(supervisor={"tolerance": 1e-4})


def test_the_ramp_scales_linearly_between_warn_and_hold():
    assert ramp(0.4e-3, 0.5e-3, 2e-3) == 1.0
    assert ramp(0.5e-3, 0.5e-3, 2e-3) == 1.0
    assert ramp(1.25e-3, 0.5e-3, 2e-3) == pytest.approx(0.5, abs=1e-15)
    assert ramp(1.7e-3, 0.5e-3, 2e-3) == pytest.approx(0.2, abs=1e-15)
    assert ramp(2e-3, 0.5e-3, 2e-3) == 0.0
    assert ramp(float("nan"), 0.5, 2.0) == 1.0  # not measured


def test_an_operator_three_times_faster_is_scaled_and_held_on_the_plant():
    """``fast-lateral`` 3x on the MuJoCo plant without acceleration limits: the QP's
    hole error peaks at 2.7 mm in the first sweep unsupervised; supervised it is scaled
    from 0.5 mm, held from 2 mm, never ``ok`` above 0.1 mm, and the records say so."""
    plan = faster(load_scenario("fast-lateral"), 3.0)
    runs = {acting: run_plan(plan, "qp:daqp", LoopConfig(supervisor=SupervisorConfig(acting=acting)),
                             duration=0.45, plant=MUJOCO, acceleration_limits=False)
            for acting in (False, True)}
    check_supervised(runs[False], SupervisorConfig(acting=False))
    check_supervised(runs[True])
    watched, supervised = runs[False].columns, runs[True].columns
    first_sweep = slice(0, 300)
    assert np.max(watched["constraint_error"][first_sweep]) > 2.5e-3
    assert np.max(supervised["constraint_error"][first_sweep]) < 1.5e-3
    scale = supervised["supervisor_scale"]
    assert np.sum((scale > 0.0) & (scale < 1.0)) > 50 and np.sum(scale == 0.0) > 20
    metrics = runs[True].metrics()["supervisor"]
    assert metrics["scaled_steps"] == int(np.sum((scale > 0.0) & (scale < 1.0)))
    assert metrics["held_steps"] == int(np.sum(scale == 0.0)) and metrics["scale_min"] == 0.0
    assert "supervisor scaled the operator's twist to" in metrics["first_action"]
    held = int(np.flatnonzero(scale == 0.0)[0])
    record_status = runs[True].statuses[held]
    assert record_status == "constraint_degraded"
    # the loop's status degraded, the controller's own kept beside it
    counts = runs[True].metrics()
    assert sum(counts["status_counts"].values()) == sum(counts["controller_status_counts"].values())
    assert counts["status_counts"].get("constraint_degraded", 0) > counts[
        "controller_status_counts"].get("constraint_degraded", 0)


def test_a_noisy_encoder_is_never_ok_and_the_hold_says_so():
    """``--encoder-noise 1e-3`` under the 3x operator with acceleration limits: the
    measured hole error (noise included) is beyond 0.1 mm at 397 of the 400 steps (the
    true one at most 1.1 mm), none of them ``ok``; where it reaches 2 mm (19 steps) the
    twist is zero."""
    plan = faster(load_scenario("fast-lateral"), 3.0)
    result = run_plan(plan, "cjm", duration=0.4, plant=MUJOCO, acceleration_limits=True,
                      imperfections=Imperfections(encoder_noise=1e-3))
    check_supervised(result)
    c = result.columns
    assert result.metrics()["status_counts"].get("ok", 0) == 0
    assert np.sum(c["measured_constraint_error"] > 1e-4) >= 390
    assert np.sum(c["supervisor_scale"] == 0.0) >= 10
    assert np.max(c["constraint_error"]) < 2e-3  # the true error, noise left out


def test_the_message_names_the_constraint_and_the_measured_error():
    plan = faster(load_scenario("fast-lateral"), 3.0)

    constraints = plan.make_constraints()
    MUJOCO.apply_wall(constraints)
    controller = make_controller("qp:daqp", plan.robot, constraints, dt=1e-3)
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0,
                      plant=MUJOCO.make(plan.robot, 1e-3, Imperfections()))
    records = [loop.tick(plan.target(1e-3 * (i + 1))) for i in range(450)]
    held = next(r for r in records if r.supervisor_action == "held")
    assert held.status == "constraint_degraded"
    assert held.message.startswith(f"measured: hole 1 ({plan.robot.constrained_link}) "
                                   f"{1e3 * held.measured_constraint_error:.3f} mm off "
                                   "(tolerance 0.1 mm)")
    assert "supervisor held the target: twist zero" in held.message
    assert held.controller_status in ("ok", "scaled", "least_squares", "constraint_degraded")


def test_the_command_line_sets_the_thresholds_into_metrics_json(tmp_path):
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "teleop.cli", "compare", "--scenario",
                          "fast-lateral", "--controllers", "qp:daqp", "--duration", "0.05",
                          "--plant", "mujoco", "--no-plots", "--quiet", "--out", str(out),
                          "--measured-tolerance", "0.2,0.8", "--supervisor-error", "1,3",
                          "--supervisor-force", "1,4", "--no-supervisor"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    document = json.loads((out / "metrics.json").read_text())
    jsonschema.validate(document, SCHEMA)
    assert document["supervisor"] == {
        "tolerance_m": 2e-4, "error_warn_m": 1e-3, "error_hold_m": 3e-3,
        "force_tolerance_n": 0.8, "force_warn_n": 1.0, "force_hold_n": 4.0,
        "release_time_s": 0.1, "acting": False}
    assert "supervisor measuring only" in run.stdout
    bad = subprocess.run([sys.executable, "-m", "teleop.cli", "compare", "--scenario",
                          "fast-lateral", "--supervisor-error", "3,2", "--out", str(out)],
                         capture_output=True, text=True, timeout=600)
    assert bad.returncode != 0 and "error_warn must be below error_hold" in bad.stderr


def test_the_ui_status_line_says_what_the_supervisor_measured_and_did():
    from web.app import supervision_words

    calm = Supervision(2e-5, 0.01, 1.0, "none", "", "")
    assert supervision_words(None) == "" and supervision_words(calm) == ""
    held = Supervision(2.3e-3, 2.4, 0.0, "held", "hole 1 (link_6) 2.300 mm off (tolerance 0.1 mm)",
                       "supervisor held the target: twist zero (hole 1 (link_6) 2.300 mm off; "
                       "warn 0.5 mm, hold 2 mm)")
    assert supervision_words(held) == (
        "measured: hole 1 (link_6) 2.300 mm off (tolerance 0.1 mm); supervisor held the "
        "target: twist zero (hole 1 (link_6) 2.300 mm off; warn 0.5 mm, hold 2 mm)")
    assert held.status_of("least_squares", "joint 3 at its limit") == (
        "constraint_degraded", f"measured: {held.breach}; {held.words}; controller: "
        "least_squares, joint 3 at its limit")
    assert held.status_of("failed", "no command")[0] == "failed"
