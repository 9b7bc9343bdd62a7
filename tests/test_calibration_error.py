"""Calibration error (docs/design.md section 15.1, "Calibration error"): the true robot's
joint placements ``M_j E_j`` against Pinocchio and the stated stds, its seed stream, the
loop's measures on the true kinematics against an independent computation, and the
refusals."""

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
from hypothesis.extra.numpy import arrays

from constraints import Barrier, Hole, Plane, PointLock
from constraints.kinematics import frame_placement
from teleop import load_robot
from teleop.cli.main import main
from teleop.controller_specs import make_controller
from teleop.experiments.compare import compare, run_plan
from teleop.experiments.scenarios import load_scenario
from teleop.loop import LoopConfig, TeleopLoop
from teleop.plants.calibration import miscalibrated_model
from teleop.plants.choice import PlantChoice
from teleop.plants.imperfect import ImperfectPlant, Imperfections

from strategies import placements

#: the draw's seed words as docs/design.md 15.1 states them, written here again
STREAM = 0xCA1


def stated_draw(joints: int, seed: int) -> np.ndarray:
    """The standard normals of the documented draw: the child ``0xCA1`` of the seed's
    ``SeedSequence``, one row ``[t / s_m, r / s_rad]`` per joint."""
    sequence = np.random.SeedSequence(seed, spawn_key=(STREAM,))
    return np.random.default_rng(sequence).standard_normal((joints, 6))


def joint_errors(model: pin.Model, true_model: pin.Model) -> list[pin.SE3]:
    """``E_j = M_j^-1 M_j,true`` for every joint ``j >= 1``."""
    return [model.jointPlacements[j].inverse() * true_model.jointPlacements[j]
            for j in range(1, model.njoints)]


# ----------------------------------------------------------------------------- the draw


@pytest.mark.parametrize("name", ["sda10f", "sda10f_dual_mobile"])
def test_true_placements_are_the_model_times_the_stated_errors(name):
    """Each ``E_j`` is ``(exp3(s_rad z[3:]), s_m z[:3])`` of the stated draw; Pinocchio's
    forward kinematics of the true model chain ``M_j E_j X_J(q)``, ``X_J`` the model's
    joint motion; frames and limits are the model's, the model is not changed."""
    model = load_robot(name).model
    before = [pin.SE3(placement) for placement in model.jointPlacements]
    position_std, rotation_std, seed = 1e-3, 2e-3, 11
    true_model = miscalibrated_model(model, position_std, rotation_std, seed)
    normals = stated_draw(model.njoints - 1, seed)
    for error, row in zip(joint_errors(model, true_model), normals):
        np.testing.assert_allclose(error.translation, position_std * row[:3], atol=1e-15)
        np.testing.assert_allclose(pin.log3(error.rotation), rotation_std * row[3:], atol=1e-14)
    assert all(p.isApprox(model.jointPlacements[j], 0.0) for j, p in enumerate(before))
    assert [f.name for f in true_model.frames] == [f.name for f in model.frames]
    np.testing.assert_array_equal(true_model.upperPositionLimit, model.upperPositionLimit)
    q = pin.randomConfiguration(model, np.maximum(model.lowerPositionLimit, -3.0),
                                np.minimum(model.upperPositionLimit, 3.0))
    nominal, true = model.createData(), true_model.createData()
    pin.forwardKinematics(model, nominal, q)
    pin.forwardKinematics(true_model, true, q)
    for j in range(1, model.njoints):
        motion = model.jointPlacements[j].inverse() * nominal.liMi[j]  # X_J(q)
        expected = true_model.jointPlacements[j] * motion
        assert true.liMi[j].isApprox(expected, 1e-12), j
        parent = model.parents[j]
        assert true.oMi[j].isApprox(true.oMi[parent] * expected, 1e-12), j


def test_the_errors_have_the_stated_std():
    """Over 50 seeds of the two-arm mobile SDA10F (N = 50 x 18 joints x 3 axes = 2700
    samples per part), each part's ``z = t / s_m`` and ``z = log3(R) / s_rad`` are
    N(0, 1): the mean square's standard error is ``sqrt(2 / N)`` and the mean's
    ``1 / sqrt(N)``; both are asked within 5 standard errors, as is the correlation of
    the two parts (independent draws)."""
    model = load_robot("sda10f_dual_mobile").model
    position_std, rotation_std = 2e-3, 5e-3
    translations, rotations = [], []
    for seed in range(50):
        for error in joint_errors(model, miscalibrated_model(model, position_std, rotation_std,
                                                             seed)):
            translations.append(error.translation / position_std)
            rotations.append(pin.log3(error.rotation) / rotation_std)
    for z in (np.ravel(translations), np.ravel(rotations)):
        n = z.size
        assert n == 50 * (model.njoints - 1) * 3
        assert abs(np.mean(z)) < 5.0 / math.sqrt(n)
        assert abs(np.mean(z * z) - 1.0) < 5.0 * math.sqrt(2.0 / n)
    correlation = np.mean(np.ravel(translations) * np.ravel(rotations))
    assert abs(correlation) < 5.0 / math.sqrt(len(np.ravel(translations)))


def test_the_draw_is_reproducible_by_seed_and_apart_from_the_encoder_noise(sda10f):
    model = sda10f.model
    first = Imperfections(seed=4, calibration_position_std=1e-3, calibration_rotation_std=2e-3)
    again = first.true_model(model)
    for a, b in zip(first.true_model(model).jointPlacements, again.jointPlacements):
        np.testing.assert_array_equal(a.homogeneous, b.homogeneous)
    other = Imperfections(seed=5, calibration_position_std=1e-3,
                          calibration_rotation_std=2e-3).true_model(model)
    assert not np.allclose(other.jointPlacements[1].translation, again.jointPlacements[1].translation)
    # a zero rotation std keeps the translations of the same draw
    translations_only = Imperfections(seed=4, calibration_position_std=1e-3).true_model(model)
    for a, b in zip(joint_errors(model, translations_only), joint_errors(model, again)):
        np.testing.assert_allclose(a.translation, b.translation, atol=1e-15)
        np.testing.assert_allclose(a.rotation, np.eye(3), atol=1e-15)
    # the encoder noise of a seed is its sequence with or without a calibration error:
    # default_rng(seed)'s normals, as before the calibration error existed
    q = sda10f.q_home
    noisy = ImperfectPlant(Imperfections(encoder_noise=1e-3, seed=4), model, 1e-3)
    both = ImperfectPlant(Imperfections(encoder_noise=1e-3, seed=4, calibration_position_std=1e-3,
                                        calibration_rotation_std=2e-3), model, 1e-3)
    rng = np.random.default_rng(4)
    for _ in range(5):
        expected = pin.integrate(model, q, rng.normal(0.0, 1e-3, model.nv))
        np.testing.assert_array_equal(noisy.sense(q), expected)
        np.testing.assert_array_equal(both.sense(q), expected)


# ----------------------------------------------------------------------------- the loop


def _paper_hole_loop(imperfections: Imperfections, compiled_tick: bool = True):
    plan = load_scenario("paper-hole")
    config = LoopConfig()
    controller = make_controller("cjm", plan.robot, plan.make_constraints(), dt=config.dt,
                                 time_budget=None)
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=config,
                      plant=imperfections.plant(plan.robot.model, config.dt),
                      compiled_tick=compiled_tick,
                      true_model=imperfections.true_model(plan.robot.model))
    return plan, loop


def _lateral_offset(center: np.ndarray, link: pin.SE3, axis: np.ndarray) -> float:
    """Distance (m) from ``center`` to the line through ``link``'s origin along its
    ``axis`` (link coordinates), all in one world."""
    direction = link.rotation @ axis
    offset = center - link.translation
    return float(np.linalg.norm(offset - (offset @ direction) * direction))


def test_the_hole_error_starts_at_zero_and_grows_as_pinocchio_computes_it():
    """paper-hole for 2 s, 1 mm / 2 mrad: the real trocar is where the true link passed at
    q0, ``c' = T_true(q0) T_model(q0)^-1 c``; at every tick the measured error is the
    offset of the true link axis from ``c'``, computed here with Pinocchio on the true
    model. It starts below 1e-9 m and ends above 0.1 mm, 500 times the perfect robot's
    1.8e-7 m."""
    imperfections = Imperfections(seed=0, calibration_position_std=1e-3,
                                  calibration_rotation_std=2e-3)
    plan, loop = _paper_hole_loop(imperfections)
    assert loop.compiled is not None  # the hot path stays compiled: it is the controller's
    model, true_model = plan.robot.model, imperfections.true_model(plan.robot.model)
    hole = loop.constraints[0]
    frame = model.getFrameId(hole.link)
    nominal, true = model.createData(), true_model.createData()
    pin.framesForwardKinematics(model, nominal, plan.q0)
    pin.framesForwardKinematics(true_model, true, plan.q0)
    center = true.oMf[frame].act(nominal.oMf[frame].actInv(hole.center))
    measured, expected = [], []
    for i in range(2000):
        record = loop.tick(plan.target((i + 1) * loop.config.dt))
        pin.framesForwardKinematics(true_model, true, loop.q)
        measured.append(record.constraint_errors[0])
        expected.append(_lateral_offset(center, true.oMf[frame], hole.link_axis))
    np.testing.assert_allclose(measured, expected, rtol=1e-9, atol=1e-14)
    assert measured[0] < 1e-9
    assert max(measured) > 1e-4


def test_zero_calibration_error_is_the_perfect_robot_bit_for_bit():
    """Zero stds: no true model, no plant, the compiled tick; every column as without
    imperfections; with encoder noise, every column as the same noise alone."""
    plan = load_scenario("paper-hole")
    zero = Imperfections(seed=3, calibration_position_std=0.0, calibration_rotation_std=0.0)
    assert zero.perfect and zero.true_model(plan.robot.model) is None
    assert zero.plant(plan.robot.model, 1e-3) is None
    _, loop = _paper_hole_loop(zero)
    assert loop.true_kinematics is None and loop.compiled is not None
    for imperfect in (None, Imperfections(encoder_noise=1e-4, latency=1, seed=3)):
        zeroed = None if imperfect is None else Imperfections(
            imperfect.encoder_noise, imperfect.latency, imperfect.joint_time_constant,
            imperfect.seed, 0.0, 0.0)
        base = run_plan(plan, "cjm", duration=0.3, imperfections=imperfect)
        same = run_plan(plan, "cjm", duration=0.3, imperfections=zeroed or zero)
        for name, column in base.columns.items():
            if name not in ("step_time_us", "tick_time_us"):
                np.testing.assert_array_equal(same.columns[name], column, err_msg=name)


def test_a_true_model_equal_to_the_model_measures_as_the_model():
    """The true-kinematics path with an exact copy of the model (``G`` the identity up to
    rounding): every error as the model's path measures it, to rounding."""
    plan = load_scenario("moving-trocar")
    config = LoopConfig()
    runs = []
    for true_model in (None, pin.Model(plan.robot.model)):
        constraints = plan.make_constraints()
        controller = make_controller("cjm", plan.robot, constraints, dt=config.dt,
                                     time_budget=None)
        loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=config,
                          true_model=true_model)
        records = []
        for i in range(300):
            changed = plan.update(i * config.dt, loop.constraints, loop.q)
            if changed is not None:
                loop.set_constraints(changed)
            records.append(loop.tick(plan.target((i + 1) * config.dt),
                                     lambda now: plan.update(now, loop.constraints, loop.q)))
        runs.append(records)
    for exact, copied in zip(*runs):
        np.testing.assert_allclose(copied.constraint_errors, exact.constraint_errors, atol=1e-15)
        np.testing.assert_allclose(copied.ee_position_errors, exact.ee_position_errors,
                                   atol=1e-15)
        np.testing.assert_allclose(copied.constraint_velocity, exact.constraint_velocity,
                                   atol=1e-12)
        np.testing.assert_allclose(copied.actual_linear_velocities,
                                   exact.actual_linear_velocities, atol=1e-14)


def error_world(constraint, placement: pin.SE3) -> np.ndarray:
    """The constraint's error as a world vector, ``R_a C^T e``."""
    return placement.rotation @ (constraint.directions(placement).T @ constraint.error(placement))


@pytest.mark.parametrize("kind", ["hole", "plane", "point_lock", "barrier"])
def test_a_moved_constraint_keeps_its_error_at_the_moved_placement(sda10f, kind):
    """``c.moved(G)`` at ``G T`` errs as ``c`` at ``T`` (the same violation, the world
    error rotated by ``R_G``, the same feed-forward in link coordinates); its world point
    is ``G x``, its velocity ``R_G v``; the original is unchanged."""
    q = sda10f.q_home
    link = sda10f.constrained_link
    constraint = {
        "hole": lambda: Hole.on_link(sda10f, q, 0.08),
        "plane": lambda: Plane.through_link_point(sda10f, q, (0.0, 0.6, 0.8), distance=0.05),
        "point_lock": lambda: PointLock.on_link(sda10f, q, distance=0.05),
        "barrier": lambda: Barrier.through_link_point(sda10f, q, (0.0, 0.0, 1.0),
                                                      distance=0.05),
    }[kind]()
    constraint.move_to(constraint.position + 0.01, velocity=(0.01, -0.02, 0.03))
    before = constraint.to_dict()
    motion = pin.SE3(pin.exp3(np.array([0.1, -0.2, 0.3])), np.array([0.02, -0.01, 0.03]))
    moved = constraint.moved(motion)
    assert constraint.to_dict() == before and type(moved) is type(constraint)
    np.testing.assert_allclose(moved.position, motion.act(constraint.position), atol=1e-15)
    np.testing.assert_allclose(moved.velocity, motion.rotation @ constraint.velocity, atol=1e-15)
    for placement in (frame_placement(sda10f.model, q, link),
                      frame_placement(sda10f.model, q + 0.1, link)):
        there = motion * placement
        assert moved.violation(there) == pytest.approx(constraint.violation(placement),
                                                       rel=1e-12, abs=1e-15)
        np.testing.assert_allclose(error_world(moved, there),
                                   motion.rotation @ error_world(constraint, placement),
                                   atol=1e-15)
        # the geometry's velocity along the constrained directions, in link coordinates
        np.testing.assert_allclose(moved.directions(there).T @ moved.feed_forward(there),
                                   constraint.directions(placement).T
                                   @ constraint.feed_forward(placement), atol=1e-15)


@settings(max_examples=25, deadline=None)
@given(offset=arrays(float, 8, elements=st.floats(-0.3, 0.3)), target=placements(),
       seed=st.integers(0, 10_000))
def test_measured_errors_are_those_of_the_true_model(sda10f, offset, target, seed):
    """At any configuration: the measured EE errors are the distance and the rotation
    angle between the true model's EE placement (Pinocchio) and the target; a hole placed
    there errs by the offset of the true link axis from where the true link met it."""
    model = sda10f.model
    imperfections = Imperfections(seed=seed, calibration_position_std=1e-3,
                                  calibration_rotation_std=2e-3)
    true_model = imperfections.true_model(model)
    q = pin.integrate(model, sda10f.q_home, offset)
    hole = Hole.on_link(sda10f, q, 0.08)
    controller = make_controller("cjm", sda10f, [hole], time_budget=None)
    loop = TeleopLoop(sda10f, controller, q0=q, true_model=true_model)
    target = pin.SE3(target.rotation, home_position(sda10f) + 0.1 * target.translation)
    record = loop.tick(target)
    true = true_model.createData()
    nominal = model.createData()
    pin.framesForwardKinematics(true_model, true, loop.q)
    ee = true.oMf[model.getFrameId(sda10f.ee_frame)]
    assert record.ee_position_errors[0] == pytest.approx(
        np.linalg.norm(ee.translation - target.translation), rel=1e-12, abs=1e-15)
    assert record.ee_orientation_errors[0] == pytest.approx(
        np.linalg.norm(pin.log3(ee.rotation.T @ target.rotation)), rel=1e-9, abs=1e-12)
    frame = model.getFrameId(hole.link)
    pin.framesForwardKinematics(model, nominal, q)
    start = true_model.createData()
    pin.framesForwardKinematics(true_model, start, q)
    center = start.oMf[frame].act(nominal.oMf[frame].actInv(hole.center))
    assert record.constraint_errors[0] == pytest.approx(
        _lateral_offset(center, true.oMf[frame], hole.link_axis), rel=1e-9, abs=1e-14)


def home_position(robot) -> np.ndarray:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_home)
    return data.oMf[robot.model.getFrameId(robot.ee_frame)].translation.copy()


# ----------------------------------------------------------------------------- refusals


@pytest.mark.parametrize("field, value", [
    ("calibration_position_std", -1e-3), ("calibration_position_std", math.nan),
    ("calibration_position_std", 0.06), ("calibration_position_std", "0.001"),
    ("calibration_position_std", True), ("calibration_rotation_std", math.inf),
    ("calibration_rotation_std", 0.3), ("calibration_rotation_std", -0.1),
])
def test_bad_calibration_errors_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        Imperfections(**{field: value})


def test_the_mujoco_plant_refuses_a_calibration_error_before_simulating(sda10f):
    imperfections = Imperfections(calibration_rotation_std=1e-3)
    with pytest.raises(ValueError, match="calibration error"):
        PlantChoice("mujoco").make(sda10f, 1e-3, imperfections)
    with pytest.raises(ValueError, match="calibration error"):
        compare(load_scenario("paper-hole"), ["cjm"], duration=0.01, progress=False,
                imperfections=imperfections, plant=PlantChoice("mujoco"))


@pytest.mark.parametrize("value, message", [
    ("1", "expected MM,MRAD"), ("1,2,3", "expected MM,MRAD"),
    ("x,2", "position std must be a number"), ("-1,2", "position std must be in [0, 50] mm"),
    ("1,201", "rotation std must be in [0, 200] mrad"), ("1,nan", "rotation std must be"),
])
@pytest.mark.parametrize("command", [["compare", "--scenario", "paper-hole"],
                                     ["replay", "session.jsonl"]])
def test_bad_calibration_error_flags_are_one_line_and_exit_2(command, value, message, capsys):
    with pytest.raises(SystemExit) as exit_:
        main([*command, f"--calibration-error={value}"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "--calibration-error" in err, err
    assert message in err, err


def test_the_flag_reaches_metrics_json_and_the_mujoco_plant_refuses_it(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["compare", "--scenario", "paper-hole", "--controllers", "cjm", "--duration",
                 "0.05", "--calibration-error", "1,2", "--seed", "3", "--no-plots", "--quiet",
                 "--out", str(out)]) == 0
    assert "calibration error 1 mm, 2 mrad (seed 3)" in capsys.readouterr().out
    document = json.loads((out / "metrics.json").read_text())
    jsonschema.validate(document, json.loads(
        files("teleop.experiments").joinpath("metrics.schema.json").read_text()))
    assert document["imperfections"] == {
        "encoder_noise_rad": 0.0, "latency_periods": 0, "joint_time_constant_s": 0.0,
        "seed": 3, "calibration_position_std_m": 1e-3, "calibration_rotation_std_rad": 2e-3}
    assert main(["compare", "--scenario", "paper-hole", "--calibration-error", "1,2",
                 "--plant", "mujoco", "--quiet", "--out", str(tmp_path / "mujoco")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "calibration error" in err, err


def test_the_calibration_stream_is_no_other_seeds_encoder_noise():
    """``default_rng([s, c])`` would be the seed ``s + c 2^32``'s encoder noise; the
    child stream of the seed is not (teleop/seeds.py)."""
    seed = 5
    colliding_seed = seed + STREAM * 2**32
    ours = stated_draw(3, seed).ravel()
    assert not np.allclose(ours, np.random.default_rng(colliding_seed).standard_normal(18))
    assert np.array_equal(np.random.default_rng([seed, STREAM]).standard_normal(3),
                          np.random.default_rng(colliding_seed).standard_normal(3))
