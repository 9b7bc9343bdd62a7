"""Recorded sessions replay step for step; the CLI works end to end as a user runs it."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from teleop.experiments.compare import run_plan
from teleop.experiments.scenarios import load_scenario
from teleop.experiments.sessions import (
    SessionError,
    load_session,
    record_plan,
    session_plan,
)
from teleop.loop.moving_geometry import MAX_GEOMETRY_SPEED

COMPARED = ("constraint_error", "constraint_velocity_residual", "barrier_penetration",
            "ee_position_error", "ee_orientation_error", "joint_limit_violation", "failed")


@pytest.mark.parametrize("scenario", ["trocar-circle", "moving-trocar"])
def test_replay_of_a_recorded_scenario_reproduces_compare(scenario, tmp_path):
    plan = load_scenario(scenario)
    path = record_plan(plan, tmp_path / "session.jsonl", duration=0.4)
    replayed = run_plan(session_plan(load_session(path)), "cjm")
    direct = run_plan(plan, "cjm", duration=0.4)
    assert replayed.steps == direct.steps == 400
    # the only difference is the target's rotation round trip through a unit quaternion
    for column in COMPARED:
        np.testing.assert_allclose(replayed.columns[column], direct.columns[column],
                                   rtol=1e-6, atol=1e-12, err_msg=column)
    np.testing.assert_allclose(replayed.constraint_velocity, direct.constraint_velocity,
                               rtol=1e-6, atol=1e-12)


def write_session(path, lines):
    path.write_text("\n".join(json.dumps(line) for line in lines) + "\n")
    return path


def header(robot="ur5_instrument"):
    from teleop import load_robot

    return {"type": "header", "format": "cjm-teleop-session", "version": 1, "robot": robot,
            "q0": load_robot(robot).q_home.tolist(), "rate_hz": 1000, "kp": 20,
            "target_time_constant_s": 0.05}


def test_constraints_added_and_removed_mid_session(tmp_path, ur5_instrument):
    import pinocchio as pin

    from constraints import Hole
    from teleop.experiments.scenarios import home_pose

    hole = Hole.on_link(ur5_instrument, ur5_instrument.q_home, distance=0.2)
    home = home_pose(ur5_instrument, ur5_instrument.q_home)
    quaternion = pin.Quaternion(home.rotation)
    path = write_session(tmp_path / "edits.jsonl", [
        header(),
        {"type": "add", "t": 0.1, "id": "h", "constraint": hole.to_dict()},
        {"type": "target", "t": 0.0, "position": home.translation.tolist(),
         "quaternion_wxyz": [quaternion.w, quaternion.x, quaternion.y, quaternion.z]},
        {"type": "move", "t": 0.15, "id": "h", "position": (hole.center + [0.002, 0, 0]).tolist()},
        {"type": "remove", "t": 0.3, "id": "h"},
        {"type": "end", "t": 0.4},
    ])
    session = load_session(path)
    assert session.duration == 0.4
    plan = session_plan(session)
    result = run_plan(plan, "qp:daqp")
    error = result.columns["constraint_error"]
    assert np.all(error[:99] == 0.0)  # no constraint yet
    assert error[120] < 1e-6  # the hole, placed on the axis, is held
    # the 2 mm jump glides at MAX_GEOMETRY_SPEED (0.1 s) with feed-forward: held throughout
    assert np.max(error[100:300]) < 1e-5
    assert np.all(error[301:] == 0.0)  # removed
    # the glide: replaying the edits alone, the centre moves at most 0.02 m/s and arrives
    constraints = plan.make_constraints()
    centres = []
    for i in range(300):
        constraints = plan.update(i * 1e-3, constraints, ur5_instrument.q_home) or constraints
        centres.append(constraints[0].position.copy() if constraints else None)
    steps = np.linalg.norm(np.diff(np.array(centres[100:299]), axis=0), axis=1)
    assert np.max(steps) <= MAX_GEOMETRY_SPEED * 1e-3 * (1 + 1e-9)
    np.testing.assert_allclose(centres[298], hole.center + [0.002, 0, 0], atol=1e-12)


@pytest.mark.parametrize("line, message", [
    ("{not json", r"edits.jsonl:2: not JSON"),
    ('{"type": "teleport", "t": 0}', r"edits.jsonl:2: unknown event type 'teleport'"),
    ('{"type": "target", "t": -1, "position": [0,0,0], "quaternion_wxyz": [1,0,0,0]}', r"'t' must be a time"),
    ('{"type": "target", "t": 0, "position": [0,0,0], "quaternion_wxyz": [2,0,0,0]}',
     r"quaternion must be unit"),
    ('{"type": "add", "t": 0, "id": "x", "constraint": {"kind": "wormhole"}}',
     r"unknown constraint kind 'wormhole'"),
])
def test_bad_session_lines_are_named(tmp_path, line, message):
    path = tmp_path / "edits.jsonl"
    path.write_text(json.dumps(header()) + "\n" + line + "\n")
    with pytest.raises(SessionError, match=message):
        load_session(path)


def test_moving_an_unknown_constraint_fails_at_its_line(tmp_path):
    path = write_session(tmp_path / "s.jsonl", [
        header(), {"type": "move", "t": 0.01, "id": "ghost", "position": [0, 0, 0]}])
    with pytest.raises(SessionError, match=r"s.jsonl:2: no constraint with id 'ghost'"):
        run_plan(session_plan(load_session(path)), "cjm", duration=0.05)


def test_geometry_off_its_link_is_refused_at_its_line(tmp_path, ur5_instrument):
    from constraints import Hole

    hole = Hole.on_link(ur5_instrument, ur5_instrument.q_home, distance=0.2)
    far = Hole(hole.link, hole.center + [0.1, 0.0, 0.0], link_axis=hole.link_axis)
    path = write_session(tmp_path / "s.jsonl", [
        header(), {"type": "add", "t": 0.01, "id": "h", "constraint": far.to_dict()}])
    with pytest.raises(SessionError, match=r"s.jsonl:2: the hole is 0.1 m off link 'instrument_shaft'"):
        run_plan(session_plan(load_session(path)), "cjm", duration=0.05)


def teleop(*args, cwd):
    return subprocess.run([sys.executable, "-m", "teleop.cli", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def test_cli_compare_record_replay_and_bench(tmp_path):
    out = tmp_path / "out"
    run = teleop("compare", "--scenario", "trocar-circle", "--controllers", "cjm,qp:daqp,mink:daqp",
                 "--duration", "0.2", "--out", str(out), "--quiet", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "| cjm |" in run.stdout and "| mink:daqp |" in run.stdout
    document = json.loads((out / "metrics.json").read_text())
    assert set(document["controllers"]) == {"cjm", "qp:daqp", "mink:daqp"}
    csv_lines = (out / "metrics.csv").read_text().splitlines()
    assert csv_lines[0].startswith("controller,constraint_error_max_m") and len(csv_lines) == 4
    assert (out / "report.html").stat().st_size > 50_000  # the plots are in it

    session = tmp_path / "circle.jsonl"
    assert teleop("record", "--scenario", "trocar-circle", "--duration", "0.2", str(session),
                  cwd=tmp_path).returncode == 0
    replay = teleop("replay", str(session), "--controllers", "cjm,qp:daqp", "--out",
                    str(tmp_path / "replay"), "--quiet", "--no-plots", cwd=tmp_path)
    assert replay.returncode == 0, replay.stderr
    assert not (tmp_path / "replay" / "report.html").exists()  # --no-plots: metrics only
    replayed = json.loads((tmp_path / "replay" / "metrics.json").read_text())
    for spec in ("cjm", "qp:daqp"):
        for key in ("constraint_error_max_m", "ee_position_error_rms_m"):
            assert replayed["controllers"][spec][key] == pytest.approx(
                document["controllers"][spec][key], rel=1e-6, abs=1e-12)

    bench = teleop("bench", "--quick", "--robots", "ur5_instrument", "--controllers",
                   "cjm,qp:daqp,mink:daqp", "--json", str(tmp_path / "bench.json"), cwd=tmp_path)
    assert bench.returncode == 0, bench.stderr
    assert "ur5_instrument" in bench.stdout
    assert json.loads((tmp_path / "bench.json").read_text())


def test_cli_imperfect_robot_options_are_recorded(tmp_path):
    out = tmp_path / "out"
    run = teleop("compare", "--scenario", "paper-hole", "--controllers", "cjm", "--duration",
                 "0.1", "--encoder-noise", "1e-4", "--latency", "2", "--joint-time-constant",
                 "0.005", "--seed", "9", "--no-plots", "--out", str(out), "--quiet", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "encoder noise 0.0001 rad, latency 2 periods, joint time constant 0.005 s (seed 9)" \
        in run.stdout
    document = json.loads((out / "metrics.json").read_text())
    assert document["imperfections"] == {"encoder_noise_rad": 1e-4, "latency_periods": 2,
                                         "joint_time_constant_s": 0.005, "seed": 9,
                                         "calibration_position_std_m": 0.0,
                                         "calibration_rotation_std_rad": 0.0}


def test_cli_replay_keeps_the_solver_off_the_console(tmp_path, ur5_instrument):
    """A session with no constraint: OSQP has no active set on any step and prints from C
    every time; the run's output is the table alone, the lines are counted in metrics.json."""
    import pinocchio as pin

    from teleop.experiments.scenarios import home_pose

    home = home_pose(ur5_instrument, ur5_instrument.q_home)
    quaternion = pin.Quaternion(home.rotation)
    path = write_session(tmp_path / "free.jsonl", [
        header(),
        {"type": "target", "t": 0.0, "position": (home.translation + [0.005, 0, 0]).tolist(),
         "quaternion_wxyz": [quaternion.w, quaternion.x, quaternion.y, quaternion.z]},
        {"type": "end", "t": 0.1},
    ])
    # without acceleration limits no bound binds either (with them the box is active)
    run = teleop("replay", str(path), "--controllers", "qp:osqp", "--out", str(tmp_path / "out"),
                 "--no-plots", "--no-acceleration-limits", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "Polishing" not in run.stdout + run.stderr
    # standard error holds the progress alone when it is not a terminal: a line at each
    # tenth of the run's steps with the time left, then one when the run is done
    assert re.fullmatch(r"(free: qp:osqp \d+% \(\d+/100 steps, [^\n]*left\)\n)*"
                        r"free: qp:osqp done \(1/1, 100 steps in [0-9.]+ s\)\n", run.stderr), run.stderr
    assert "qp:osqp: the solver wrote 100 lines (1 distinct), kept in metrics.json" in run.stdout
    document = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert document["controllers"]["qp:osqp"]["solver_messages"] == {
        "Polishing not needed - no active set detected at optimal point": 100}


@pytest.mark.parametrize("option, value", [("--encoder-noise", "-1e-4"), ("--latency", "1.5"),
                                           ("--joint-time-constant", "inf"), ("--seed", "-1")])
def test_cli_refuses_a_bad_imperfection_by_name(tmp_path, option, value):
    run = teleop("compare", "--scenario", "barrier", option, value, cwd=tmp_path)
    assert run.returncode == 2
    assert f"argument {option}" in run.stderr and "Traceback" not in run.stderr


@pytest.mark.parametrize("args, message", [
    (["compare", "--scenario", "nope"], "unknown scenario 'nope'"),
    (["compare", "--scenario", "barrier", "--controllers", "lqr"], "unknown controller 'lqr'"),
    (["compare", "--scenario", "barrier", "--controllers", "qp:cplex"], "'cplex' is not available"),
    (["replay", "missing.jsonl"], "no session file at missing.jsonl"),
    (["compare", "--scenario", "barrier", "--controllers", "cjm,cjm"], "specs lists 'cjm' twice"),
])
def test_cli_errors_are_one_clear_line(tmp_path, args, message):
    run = teleop(*args, cwd=tmp_path)
    assert run.returncode == 2
    assert message in run.stderr and "Traceback" not in run.stderr
