"""Random trocar placements and operator paths (teleop/experiments/variations.py) and the
gains as compare inputs (docs/design.md section 15.1.1)."""

from __future__ import annotations

import json
import math
from importlib.resources import files

import jsonschema
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from constraints import Barrier, Hole, Plane, PointLock
from teleop.cli.main import main
from teleop.experiments.compare import compare, metrics_document, run_plan
from teleop.experiments.plan import Plan, home_pose
from teleop.experiments.scenarios import load_scenario
from teleop.experiments.variations import (PATH_FREQUENCY_RANGE_HZ, PATH_RAMP_S, PATH_TERMS,
                                           Variation)
from teleop.limits import MAX_PATH_AMPLITUDE_M, MAX_TROCAR_SHIFT_M
from teleop.loop import LoopConfig

SCHEMA = json.loads(files("teleop.experiments").joinpath("metrics.schema.json").read_text())
#: columns that hold wall-clock times (not reproducible run to run)
TIMES = ("step_time_us", "tick_time_us")
seeds = st.integers(0, 2**32)
shifts = st.floats(0.0, 0.2)


def link_frame(robot, q: np.ndarray, link: str) -> pin.SE3:
    """The link's world placement from Pinocchio's forward kinematics, computed here."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(link)].copy()


def four_kinds(robot, q: np.ndarray, normal: np.ndarray) -> Plan:
    """A plan at ``q`` with a hole, a plane, a barrier and a point lock on different links."""

    def make():
        return [Hole.on_link(robot, q, distance=0.08),
                Plane.through_link_point(robot, q, normal=normal, link_point=[0.0, 0.1, -0.02],
                                         link="arm_link_3_e"),
                Barrier.through_link_point(robot, q, normal, distance=0.0, link=robot.ee_frame),
                PointLock.on_link(robot, q, distance=0.05, link="arm_link_4_u")]

    start = home_pose(robot, q)
    return Plan("four", robot, q, 1.0, make, lambda t: start)


@settings(max_examples=40, deadline=None)
@given(seed=seeds, shift=shifts, spread=st.lists(st.floats(-0.3, 0.3), min_size=8, max_size=8),
       normal=st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=3).filter(
           lambda n: np.linalg.norm(n) > 0.1))
def test_every_slid_constraint_still_holds_and_moved_along_its_link(sda10f, seed, shift, spread,
                                                                    normal):
    q = sda10f.q_home + np.asarray(spread)
    plan = four_kinds(sda10f, q, np.asarray(normal) / np.linalg.norm(normal))
    originals, slid = plan.make_constraints(), Variation(trocar_shift=shift, seed=seed).apply(
        plan).make_constraints()
    for original, moved in zip(originals, slid):
        frame = link_frame(sda10f, q, original.link)
        axis = frame.rotation @ (original.link_axis if isinstance(original, Hole)
                                 else sda10f.link_axis)
        np.testing.assert_allclose(moved.error(frame), original.error(frame), atol=1e-12)
        if original.is_equality:
            np.testing.assert_allclose(moved.error(frame), 0.0, atol=1e-12)
        shift_world = moved.position - original.position
        offset = float(shift_world @ axis)
        np.testing.assert_allclose(shift_world, offset * axis, atol=1e-12)  # along the link
        assert abs(offset) <= shift + 1e-12
        # the point on the link went with the geometry: Pinocchio's placement of it
        np.testing.assert_allclose(moved.point_world(frame) - original.point_world(frame),
                                   shift_world, atol=1e-12)
    hole = slid[0]  # the centre is on the link axis: its distance to the line, from Pinocchio
    frame = link_frame(sda10f, q, hole.link)
    radial = hole.center - frame.translation
    axis = frame.rotation @ hole.link_axis
    assert np.linalg.norm(radial - (radial @ axis) * axis) < 1e-12


@settings(max_examples=20, deadline=None)
@given(seed=seeds, shift=st.floats(1e-3, 0.2))
def test_the_draws_repeat_for_a_seed_and_differ_across_seeds(sda10f, seed, shift):
    plan = four_kinds(sda10f, sda10f.q_home, np.array([0.0, 0.6, 0.8]))
    varied = Variation(trocar_shift=shift, path_amplitude=0.01, seed=seed)

    def positions(variation):
        return [c.position for c in variation.apply(plan).make_constraints()]

    again = Variation(trocar_shift=shift, path_amplitude=0.01, seed=seed)
    np.testing.assert_array_equal(positions(varied), positions(varied))  # every call alike
    np.testing.assert_array_equal(positions(varied), positions(again))
    other = Variation(trocar_shift=shift, path_amplitude=0.01, seed=seed + 1)
    assert not np.array_equal(positions(varied), positions(other))
    assert [p(3.0).tolist() for p in varied.operator_paths(2)] == \
        [p(3.0).tolist() for p in again.operator_paths(2)]
    assert not np.array_equal(varied.operator_paths(1)[0](3.0), other.operator_paths(1)[0](3.0))
    # independent of the encoder noise's stream, default_rng(seed)
    noise = np.random.default_rng(seed).uniform(-shift, shift)
    assert float(varied.trocar_rng().uniform(-shift, shift)) != noise


@settings(max_examples=40, deadline=None)
@given(seed=seeds, amplitude=st.floats(1e-4, MAX_PATH_AMPLITUDE_M))
def test_the_paths_stay_within_the_amplitude_and_start_at_rest(seed, amplitude):
    for path in Variation(path_amplitude=amplitude, seed=seed).operator_paths(2):
        assert np.all((PATH_FREQUENCY_RANGE_HZ[0] <= path.frequencies)
                      & (path.frequencies <= PATH_FREQUENCY_RANGE_HZ[1]))
        assert path.directions.shape == (PATH_TERMS, 3)
        np.testing.assert_allclose(np.linalg.norm(path.directions, axis=1), 1.0, rtol=1e-12)
        times = np.linspace(0.0, 60.0, 3001)
        norms = [np.linalg.norm(path(t)) for t in times]
        assert max(norms) <= amplitude * (1.0 + 1e-12)
        assert max(norms) > 0.0
        np.testing.assert_array_equal(path(0.0), np.zeros(3))
        h = 1e-5
        assert np.linalg.norm(path(h) - path(0.0)) / h <= 1e-6 * amplitude  # x'(0) = 0
        # after the fade-in: the three sinusoids, written here
        t = PATH_RAMP_S + 1.7
        expected = sum(amplitude / PATH_TERMS * u * math.sin(2 * math.pi * f * t + phase)
                       for u, f, phase in zip(path.directions, path.frequencies, path.phases))
        np.testing.assert_allclose(path(t), expected, atol=1e-15)


def test_the_varied_target_moves_the_translation_only(dual):
    plan = load_scenario("bimanual-trocars", dual)
    variation = Variation(path_amplitude=0.02, seed=4)
    varied = variation.apply(plan)
    paths = variation.operator_paths(2)
    for t in (0.0, 0.4, 2.5, 7.0):
        for before, after, path in zip(plan.target(t), varied.target(t), paths):
            np.testing.assert_array_equal(after.rotation, before.rotation)
            np.testing.assert_allclose(after.translation - before.translation, path(t),
                                       atol=1e-15)
    single = load_scenario("paper-hole")
    assert isinstance(variation.apply(single).target(1.0), pin.SE3)


def test_geometry_an_update_moves_or_adds_is_slid_too(ur5_instrument, tmp_path):
    """moving-trocar moves its hole each tick, a session adds its constraints at t = 0: the
    slid copy keeps the same world shift along the link as the plan's own object moves."""
    plan = load_scenario("moving-trocar", ur5_instrument)
    varied = Variation(trocar_shift=0.03, seed=1).apply(plan)
    own, slid = plan.make_constraints(), varied.make_constraints()
    shift = slid[0].center - own[0].center
    frame = link_frame(ur5_instrument, plan.q0, own[0].link)
    axis = frame.rotation @ own[0].link_axis
    assert np.linalg.norm(shift) > 1e-4
    np.testing.assert_allclose(shift, (shift @ axis) * axis, atol=1e-12)
    for t in (0.3, 1.1, 2.0):
        plan.update(t, own, plan.q0)
        varied.update(t, slid, plan.q0)
        np.testing.assert_allclose(slid[0].center - own[0].center, shift, atol=1e-15)
        np.testing.assert_array_equal(slid[0].velocity, own[0].velocity)
        assert np.linalg.norm(own[0].velocity) > 0.0
    assert main(["record", "--scenario", "moving-trocar", "--duration", "0.2",
                 str(tmp_path / "s.jsonl")]) == 0
    from teleop.experiments.sessions import load_session, session_plan

    session = session_plan(load_session(tmp_path / "s.jsonl"))
    varied = Variation(trocar_shift=0.03, seed=1).apply(session)
    assert varied.make_constraints() == []
    added = varied.update(0.0, [], session.q0)
    assert len(added) == 1
    frame = link_frame(ur5_instrument, session.q0, added[0].link)
    assert added[0].violation(frame) < 1e-12
    np.testing.assert_allclose(added[0].center, slid[0].center - (plan.make_constraints()[0].center
                                                                  - own[0].center), atol=1e-12)


def test_no_variation_leaves_every_result_as_it_was():
    plan = load_scenario("paper-hole")
    config = LoopConfig()
    plain = run_plan(plan, "cjm", config, duration=0.5)
    none = run_plan(Variation(seed=7).apply(plan), "cjm", config, duration=0.5)
    varied = run_plan(Variation(trocar_shift=0.02, path_amplitude=0.005, seed=7).apply(plan),
                      "cjm", config, duration=0.5)
    for name, column in plain.columns.items():
        if name not in TIMES:
            np.testing.assert_array_equal(none.columns[name], column, err_msg=name)
    assert not np.array_equal(varied.columns["ee_position_error"],
                              plain.columns["ee_position_error"])
    assert varied.metrics()["constraint_error_max_m"] < 1e-6  # the slid hole holds


def test_compare_records_the_variation_and_the_gains(tmp_path):
    base = ["compare", "--scenario", "paper-hole", "--duration", "1", "--controllers", "cjm",
            "--no-plots", "--quiet"]
    assert main([*base, "--out", str(tmp_path / "plain")]) == 0
    assert main([*base, "--out", str(tmp_path / "varied"), "--trocar-shift", "0.02",
                 "--path-amplitude", "0.01", "--seed", "3", "--kp", "35",
                 "--constraint-gain", "40"]) == 0
    plain, varied = (json.loads((tmp_path / name / "metrics.json").read_text())
                     for name in ("plain", "varied"))
    for document in (plain, varied):
        jsonschema.validate(document, SCHEMA)
        assert document["schema_version"] == 9
    assert plain["variation"] == {"trocar_shift_m": 0.0, "path_amplitude_m": 0.0, "seed": 0}
    assert (plain["kp"], plain["constraint_gain"]) == (20.0, None)
    assert varied["variation"] == {"trocar_shift_m": 0.02, "path_amplitude_m": 0.01, "seed": 3}
    assert (varied["kp"], varied["constraint_gain"]) == (35.0, 40.0)
    assert varied["imperfections"]["seed"] == 3
    first, second = plain["controllers"]["cjm"], varied["controllers"]["cjm"]
    assert first["ee_position_error_rms_m"] != second["ee_position_error_rms_m"]


def test_each_gain_changes_the_run():
    plan = load_scenario("paper-hole")
    plain = run_plan(plan, "cjm", LoopConfig(), duration=0.5)
    faster = run_plan(plan, "cjm", LoopConfig(kp=40.0), duration=0.5)
    stiffer = run_plan(plan.with_constraint_gain(10.0), "cjm", LoopConfig(), duration=0.5)
    assert plan.make_constraints()[0].gain == 100.0
    assert all(c.gain == 10.0 for c in plan.with_constraint_gain(10.0).make_constraints())
    assert not np.array_equal(faster.columns["ee_position_error"],
                              plain.columns["ee_position_error"])
    assert not np.array_equal(stiffer.columns["constraint_error"],
                              plain.columns["constraint_error"])
    document = metrics_document(plan.with_constraint_gain(10.0), {"cjm": stiffer},
                                LoopConfig(kp=40.0), 0.5, variation=Variation(0.01, 0.0, 2))
    jsonschema.validate(json.loads(json.dumps(document)), SCHEMA)
    assert (document["kp"], document["constraint_gain"]) == (40.0, 10.0)
    assert document["variation"] == {"trocar_shift_m": 0.01, "path_amplitude_m": 0.0, "seed": 2}


@pytest.mark.parametrize("fields, name", [
    ({"trocar_shift": -0.01}, "trocar_shift"), ({"trocar_shift": math.nan}, "trocar_shift"),
    ({"trocar_shift": MAX_TROCAR_SHIFT_M * 2}, "trocar_shift"),
    ({"trocar_shift": "0.1"}, "trocar_shift"),
    ({"path_amplitude": -1.0}, "path_amplitude"), ({"path_amplitude": math.inf}, "path_amplitude"),
    ({"path_amplitude": MAX_PATH_AMPLITUDE_M + 0.1}, "path_amplitude"),
    ({"seed": -1}, "seed"), ({"seed": 1.5}, "seed"), ({"seed": True}, "seed")])
def test_bad_variations_are_refused_naming_the_field(fields, name):
    with pytest.raises(ValueError, match=name):
        Variation(**fields)


def test_bad_gains_are_refused_naming_them():
    plan = load_scenario("barrier")
    for gain in (-1.0, math.nan, "5"):
        with pytest.raises(ValueError, match="constraint_gain"):
            plan.with_constraint_gain(gain)
    # 1500 1/s at 1 kHz: stable for the hole (K dt < 2), not for the barrier (K dt < 1)
    with pytest.raises(ValueError, match="constraint_gain.*Barrier gain 1500"):
        compare(plan.with_constraint_gain(1500.0), ["cjm"], duration=0.1, progress=False)


@pytest.mark.parametrize("args, message", [
    (["--trocar-shift=-0.1"], "--trocar-shift: must be in [0, 1] m"),
    (["--path-amplitude", "2"], "--path-amplitude: must be in [0, 1] m"),
    (["--kp", "0"], "--kp: must be in (0, 10000] 1/s"),
    (["--constraint-gain=-3"], "--constraint-gain: must be in [0, 20000] 1/s"),
    (["--constraint-gain", "2500"], "constraint_gain: Hole gain 2500 1/s is unstable")])
def test_bad_options_are_one_line_and_exit_2(args, message, capsys, tmp_path):
    try:
        code = main(["compare", "--scenario", "paper-hole", "--duration", "0.1", "--controllers",
                     "cjm", "--quiet", "--no-plots", "--out", str(tmp_path), *args])
    except SystemExit as stop:  # argparse's own refusal
        code = stop.code
    err = capsys.readouterr().err
    assert code == 2
    assert message in err and err.count("\n") == 1, err
