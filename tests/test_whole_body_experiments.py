"""Several end effectors through the experiments: the bimanual-trocars and mobile-wall
scenarios with every default controller, sessions with two targets, old session files."""

from __future__ import annotations

import json
from importlib.resources import files

import jsonschema
import numpy as np
import pinocchio as pin
import pytest

from teleop.experiments.compare import compare, metrics_document, run_plan
from teleop.experiments.scenarios import load_scenario
from teleop.experiments.sessions import (
    SessionError,
    load_session,
    record_plan,
    session_plan,
    session_robot,
)
from teleop.loop import LoopConfig

CONTROLLERS = ["cjm", "cjm:general", "qp:proxqp", "qp:daqp", "qp:osqp", "mink:daqp"]
SCHEMA = json.loads(files("teleop.experiments").joinpath("metrics.schema.json").read_text())
HOLES = ("hole 1 (arm_left_link_5_r)", "hole 2 (arm_right_link_5_r)")


def test_bimanual_trocars_every_controller_holds_both_holes_and_tracks_both_tips():
    """The issue's bound on the first 3 s (the full 10 s are in the closing note): both holes
    to 1 um, both EEs' RMS <= 1 mm, no failed step; the metrics valid against the schema."""
    plan = load_scenario("bimanual-trocars")
    results = compare(plan, CONTROLLERS, duration=3.0, progress=False, agreement=False)
    document = metrics_document(plan, results, LoopConfig(), 3.0)
    jsonschema.validate(document, SCHEMA)
    assert document["ee_frames"] == ["arm_left_link_tool0", "arm_right_link_tool0"]
    for spec, metrics in document["controllers"].items():
        assert set(metrics["constraints"]) == set(HOLES), spec
        for hole in HOLES:
            assert metrics["constraints"][hole]["error_max_m"] <= 1e-6, (spec, hole, metrics)
        for frame, errors in metrics["end_effectors"].items():
            assert errors["position_error_rms_m"] <= 1e-3, (spec, frame, errors)
        assert metrics["failed_steps"] == 0, (spec, metrics["first_failure"])
        worst = max(e["position_error_max_m"] for e in metrics["end_effectors"].values())
        assert metrics["ee_position_error_max_m"] == worst


def test_bimanual_trocars_targets_move_both_tips_on_their_own_paths():
    """The two targets are not a copy of one another: each tip moves its own 2 cm."""
    plan = load_scenario("bimanual-trocars")
    start = plan.target(0.0)
    later = [plan.target(t) for t in np.linspace(0.0, 10.0, 41)]
    offsets = np.array([[pose.translation - first.translation for pose, first in zip(poses, start)]
                        for poses in later])
    for ee in range(2):
        assert 0.015 < np.max(np.abs(offsets[:, ee, 0])) <= 0.04 + 1e-9
        assert np.max(np.abs(offsets[:, ee, 1])) < 1e-3  # forward and up, not sideways
    assert np.max(np.abs(offsets[:, 0] - offsets[:, 1])) > 0.01


@pytest.mark.parametrize("acceleration_limits", [False, True])
def test_mobile_wall_every_controller_stops_the_base_at_the_wall(acceleration_limits):
    """The targets pull the base 0.6 m forward; the wall 0.25 m ahead is reached (the front
    corners end within 1 mm of it) and never crossed by more than 1 um, with or without
    acceleration limits (their braking-aware barriers, docs/design.md 12). OSQP stops
    converging once the base is against the wall (measured: 1737 of 5000 steps failed,
    each a zero command): its failures are counted, not forbidden; so are proxqp's with
    the limits, where the two corner barriers and the acceleration box have no common
    point for a few steps and its fallback softens only the equalities (4 measured)."""
    plan = load_scenario("mobile-wall")
    model = plan.robot.model
    base = model.getFrameId("mobile_base")
    counted = {"qp:osqp"} | ({"qp:proxqp"} if acceleration_limits else set())
    for spec in CONTROLLERS:
        result = run_plan(plan, spec, duration=5.0, acceleration_limits=acceleration_limits)
        metrics = result.metrics()
        assert metrics["barrier_penetration_max_m"] <= 1e-6, (spec, metrics)
        if spec not in counted:
            assert metrics["failed_steps"] == 0, (spec, metrics["first_failure"])
        errors = result.ee_position_errors
        assert errors.shape == (5000, 2) and errors[-1].min() > 0.05  # out of reach at the wall
        assert metrics["joint_limit_violation_max_rad"] <= 1e-9, spec
    from teleop.controller_specs import make_controller
    from teleop.loop import TeleopLoop

    constraints = plan.make_constraints()
    loop = TeleopLoop(plan.robot, make_controller("qp:daqp", plan.robot, constraints), q0=plan.q0)
    for i in range(5000):
        loop.tick(plan.target((i + 1) * 1e-3))
    data = model.createData()
    pin.framesForwardKinematics(model, data, loop.q)
    distances = [barrier.signed_distance(data.oMf[base]) for barrier in constraints]
    assert max(distances) < 1e-3 and min(distances) > -1e-6


def test_a_session_with_two_targets_replays_the_plan_to_float_precision(tmp_path):
    plan = load_scenario("bimanual-trocars")
    path = record_plan(plan, tmp_path / "two.jsonl", duration=0.3)
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    header = lines[0]
    # written at the current version (3 since the header may carry collision avoidance,
    # 4 since input devices write their lines, 5 since task modes do)
    assert header["version"] == 5 and header["ee_frames"] == list(plan.robot.ee_frames)
    assert header["root_joint"] == "fixed" and header["locked_joints"] == {}
    targets = [line for line in lines if line["type"] == "target"]
    assert len(targets) == 600
    assert [t.get("frame") for t in targets[:2]] == [None, "arm_right_link_tool0"]
    replay = session_plan(load_session(path))
    for spec in ("cjm", "qp:daqp"):
        expected = run_plan(plan, spec, duration=0.3)
        replayed = run_plan(replay, spec, duration=0.3)
        np.testing.assert_allclose(replayed.ee_position_errors, expected.ee_position_errors,
                                   rtol=0, atol=1e-12)
        for name in HOLES:
            np.testing.assert_allclose(replayed.constraint_errors[name],
                                       expected.constraint_errors[name], rtol=0, atol=1e-12)


def test_a_mobile_session_records_the_planar_root(tmp_path):
    plan = load_scenario("mobile-wall")
    path = record_plan(plan, tmp_path / "mobile.jsonl", duration=0.05)
    session = load_session(path)
    robot = session_robot(session)
    assert robot.root_joint == "planar" and (robot.nq, robot.nv) == (19, 18)
    assert session_plan(session, robot).q0.shape == (19,)


def test_a_target_for_an_unknown_frame_is_refused_with_its_line(tmp_path):
    plan = load_scenario("bimanual-trocars")
    path = record_plan(plan, tmp_path / "bad.jsonl", duration=0.01)
    lines = path.read_text().splitlines()
    index = next(i for i, line in enumerate(lines) if '"frame"' in line)
    lines[index] = lines[index].replace("arm_right_link_tool0", "arm_middle_link_tool0")
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(SessionError, match=rf"bad.jsonl:{index + 1}: unknown EE frame"):
        session_plan(load_session(path))


def test_a_version_1_session_still_replays(tmp_path):
    """A file written before several EEs (version 1: no ee_frames, root_joint,
    locked_joints, no target frame) replays exactly as the same file at version 2."""
    plan = load_scenario("paper-hole")
    path = record_plan(plan, tmp_path / "new.jsonl", duration=0.2)
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    old_header = {key: value for key, value in lines[0].items()
                  if key not in ("ee_frames", "root_joint", "locked_joints")}
    old_header["version"] = 1
    old = tmp_path / "old.jsonl"
    old.write_text("\n".join(json.dumps(line) for line in [old_header, *lines[1:]]) + "\n")
    assert all("frame" not in line for line in lines[1:])
    new_result = run_plan(session_plan(load_session(path)), "cjm", duration=0.2)
    old_result = run_plan(session_plan(load_session(old)), "cjm", duration=0.2)
    np.testing.assert_array_equal(old_result.columns["ee_position_error"],
                                  new_result.columns["ee_position_error"])
    np.testing.assert_array_equal(old_result.columns["constraint_error"],
                                  new_result.columns["constraint_error"])


def test_a_session_on_a_locked_robot_replays_on_the_locked_robot(tmp_path):
    from teleop import load_robot
    from teleop.experiments.sessions import SessionRecorder

    robot = load_robot("sda10f", locked_joints=["arm_joint_7_t"])
    with SessionRecorder(tmp_path / "locked.jsonl", robot, robot.q_home) as recorder:
        recorder.target(0.01, pin.SE3.Identity())
    session = load_session(tmp_path / "locked.jsonl")
    assert session.header["locked_joints"] == {"arm_joint_7_t": [0.6]}
    replayed = session_robot(session)
    assert replayed.nv == 7 and dict(replayed.locked_joints) == {"arm_joint_7_t": (0.6,)}
