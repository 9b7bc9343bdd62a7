"""The loop's measures (docs/design.md section 7) against the reference formulas written
here: each equality's rows from :meth:`Constraint.rows` on Pinocchio's full kinematics
(``computeJointJacobians`` and every frame's placement), the end-of-period errors from
``framesForwardKinematics``. The loop evaluates each constraint once and only the frames it
reads; the numbers must be the same to the last bit."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings, strategies as st
from hypothesis.extra.numpy import arrays

from constraints import Hole
from constraints.base import ConstraintPoint
from controllers import CJMController
from teleop.controller_specs import make_controller
from teleop.experiments.bench_loop import scenario_loop
from teleop.experiments.scenarios import load_scenario
from teleop.loop import LoopConfig, StepRecord, TeleopLoop
from teleop.loop.batched_evaluation import PER_PERIOD, batched_form
from teleop.plants.imperfect import Imperfections

#: the two-arm scenario, seconds a run: its cases are the slow tier's (CONTRIBUTING.md)
TWO_ARMS = pytest.param("bimanual-trocars", marks=pytest.mark.slow)


def reference_command_measures(loop, step) -> tuple[float, np.ndarray, np.ndarray, float]:
    """``max |A qd - b|``, ``A qd - (b + K e)``, ``-K e`` and the round-off floor at the
    sensed configuration, from :meth:`Constraint.rows`."""
    model, data = loop.model, loop.model.createData()
    pin.computeJointJacobians(model, data, step.sensed)
    pin.updateFramePlacements(model, data)
    residual, floor, velocity, drift = 0.0, 0.0, [], []
    for constraint, frame in zip(loop.constraints, loop.controller.constraint_frames):
        if not constraint.is_equality:
            continue
        A, b = constraint.rows(model, data, frame)
        placement = data.oMf[frame]
        correction = -constraint.gain * constraint.error(placement)
        residual = max(residual, float(np.max(np.abs(A @ step.qd - b))))
        velocity.append(A @ step.qd - (b - correction))
        drift.append(correction)
        position = length(constraint.point_world(placement))
        floor = max(floor, float(np.max(np.abs(A) @ np.abs(step.qd))) + constraint.gain * position)
    return residual, np.concatenate(velocity), np.concatenate(drift), floor * np.finfo(float).eps


def length(vector: np.ndarray) -> float:
    """``sqrt((x^2 + y^2) + z^2)`` in Python floats: the loop's arithmetic, which has no
    BLAS call (a dot product's rounding depends on the kernel the CPU selects)."""
    x, y, z = (float(entry) for entry in vector)
    return math.sqrt(x * x + y * y + z * z)


def transposed_product(rotation: np.ndarray, target: np.ndarray) -> np.ndarray:
    """``R^T R*`` entry by entry, ``(R_0a R*_0b + R_1a R*_1b) + R_2a R*_2b``, in Python
    floats (as :func:`length`)."""
    return np.array([[(float(rotation[0, a]) * float(target[0, b])
                       + float(rotation[1, a]) * float(target[1, b]))
                      + float(rotation[2, a]) * float(target[2, b]) for b in range(3)]
                     for a in range(3)])


@pytest.mark.parametrize("scenario", ["paper-hole", "multi", "moving-trocar", "barrier",
                                      TWO_ARMS, "joint-limits"])
@pytest.mark.parametrize("compiled_tick", [True, False])
def test_the_measures_equal_the_reference_formulas(scenario, compiled_tick):
    """Every period of a short run, on the compiled tick and on the Python path: the
    command's measures and the end-of-period errors equal the reference computed
    independently, bit for bit."""
    loop, targets = scenario_loop(scenario, compiled_tick, 0.1)
    model = loop.model
    data = model.createData()
    for target in targets:
        step = loop.advance(target)
        loop.measure_command(step)
        residual, velocity, drift, floor = reference_command_measures(loop, step)
        assert step.residual == residual and step.floor == floor
        np.testing.assert_array_equal(step.constraint_velocity, velocity)
        np.testing.assert_array_equal(step.drift_velocity, drift)
        pin.computeJointJacobians(model, data, step.sensed)
        pin.updateFramePlacements(model, data)
        actual = [data.oMf[frame].rotation
                  @ (pin.getFrameJacobian(model, data, frame, pin.LOCAL)[:3] @ step.moved)
                  for frame in loop.ee_frame_ids]
        np.testing.assert_array_equal(step.actual_linear_velocities, np.array(actual))
        commanded = [placement.rotation @ twist[:3]  # the poses as pin.SE3
                     for placement, twist in zip(step.placements, step.twists)]
        np.testing.assert_array_equal(step.commanded_linear_velocities, np.array(commanded))
        previous = step.previous_targets or step.targets
        operator = [(now.translation - before.translation) / loop.config.dt
                    for now, before in zip(step.targets, previous)]
        np.testing.assert_array_equal(step.operator_linear_velocities, np.array(operator))
        record = loop.measure(step)
        pin.framesForwardKinematics(model, data, loop.q)
        violations = [constraint.violation(data.oMf[frame])
                      for constraint, frame in zip(loop.constraints,
                                                   loop.controller.constraint_frames)]
        np.testing.assert_array_equal(record.constraint_errors, violations)
        positions = [length(data.oMf[frame].translation - target.translation)
                     for frame, target in zip(loop.ee_frame_ids, step.targets)]
        np.testing.assert_array_equal(record.ee_position_errors, positions)
        angles = [length(pin.log3(transposed_product(data.oMf[frame].rotation, target.rotation)))
                  for frame, target in zip(loop.ee_frame_ids, step.targets)]
        np.testing.assert_array_equal(record.ee_orientation_errors, angles)
        assert record.joint_limit_violation == float(max(
            0.0, np.max(loop.q - model.upperPositionLimit),
            np.max(model.lowerPositionLimit - loop.q)))
    assert len(velocity) > 0  # the scenario has equality rows


def records_equal(record: StepRecord, expected: StepRecord) -> None:
    """Every field of ``record`` equal to ``expected``'s, bit for bit (NaN equal to NaN),
    but the times measured and the round-off floor, within 1e-12 relative (the batched
    measures' world point ``R p + t`` is not rounded as Pinocchio's ``act`` rounds it)."""
    for name in (field.name for field in dataclasses.fields(StepRecord)
                 if not field.name.endswith("_time_us")):
        value, wanted = getattr(record, name), getattr(expected, name)
        if name == "step_message":
            assert value.text == wanted.text
        elif name == "constraint_velocity_floor":
            assert value == pytest.approx(wanted, rel=1e-12, abs=0.0)
        elif isinstance(wanted, np.ndarray):
            np.testing.assert_array_equal(value, wanted, err_msg=name)
        elif isinstance(wanted, float) and math.isnan(wanted):
            assert math.isnan(value), name
        else:
            assert value == wanted, name


@pytest.mark.parametrize("scenario", ["paper-hole", "moving-trocar", "barrier",
                                      TWO_ARMS, "joint-limits"])
@pytest.mark.parametrize("compiled_tick", [True, False])
def test_the_measures_taken_after_the_run_are_those_taken_at_once(scenario, compiled_tick):
    """A run through ``tick_measured_later`` measured after it gives the records of the
    same run through ``tick``, bit for bit: the geometry the measures read is the one of
    each period (the moving trocar moves at every period's end, and every constraint moves
    away again before the measures are taken)."""
    plan = load_scenario(scenario)
    runs = [scenario_loop(scenario, compiled_tick, 0.15) for _ in range(2)]
    (at_once, targets), (later, _) = runs
    assert later.measures_later
    expected = [at_once.tick(target, lambda now: plan.update(now, at_once.constraints, at_once.q))
                for target in targets]
    periods = [later.tick_measured_later(target,
                                         lambda now: plan.update(now, later.constraints, later.q))
               for target in targets]
    for constraint in later.constraints:
        constraint.move_to(constraint.position + 0.01, constraint.velocity + 0.1)
    assert [period.failed for period in periods] == [record.failed for record in expected]
    assert [period.message for period in periods] == [record.message for record in expected]
    for period, record in zip(periods, expected):
        records_equal(later.measure_later(period), record)
    moved = [period.end.constraints[0].position for period in periods]
    assert (len({tuple(position) for position in moved}) > 1) == (scenario == "moving-trocar")


def paper_hole_on_a_plant(imperfections: Imperfections) -> tuple[TeleopLoop, list]:
    """``paper-hole`` (0.15 s) on the imperfect plant of ``imperfections``, the measures
    on its true kinematics."""
    plan = load_scenario("paper-hole")
    config = LoopConfig()
    controller = make_controller("cjm", plan.robot, plan.make_constraints(), dt=config.dt)
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=config,
                      plant=imperfections.plant(plan.robot.model, config.dt),
                      true_model=imperfections.true_model(plan.robot.model))
    return loop, [plan.target((i + 1) * config.dt) for i in range(150)]


@pytest.mark.parametrize("calibration_error", [0.0, 1e-3])
def test_the_measures_after_the_run_on_a_plant_are_those_taken_at_once(calibration_error):
    """On a noisy, delayed plant the command's measures are at the true configuration before
    the period with the velocity the plant applied: kept, they give ``tick``'s records bit
    for bit; with a calibration error (the true kinematics register each constraint where
    first met) the measures are taken at once, the same records."""
    imperfections = Imperfections(encoder_noise=1e-4, latency=2, seed=3,
                                  calibration_position_std=calibration_error,
                                  calibration_rotation_std=2 * calibration_error)
    (at_once, targets), (later, _) = (paper_hole_on_a_plant(imperfections) for _ in range(2))
    assert later.measures_later == (calibration_error == 0.0)
    expected = [at_once.tick(target) for target in targets]
    periods = [later.tick_measured_later(target) for target in targets]
    assert all((period.record is None) == later.measures_later for period in periods)
    for period, record in zip(periods, expected):
        records_equal(later.measure_later(period), record)
    assert max(record.constraint_error for record in expected) > 0.0


def moved_by(target, offset: np.ndarray):
    """``target`` (a pose, or one per EE) translated by ``offset`` (world, m)."""
    if isinstance(target, pin.SE3):
        return pin.SE3(target.rotation, target.translation + offset)
    return [moved_by(pose, offset) for pose in target]


@pytest.mark.slow
@settings(max_examples=10, deadline=None)
@given(scenario=st.sampled_from(["paper-hole", "moving-trocar", "barrier", "bimanual-trocars",
                                 "joint-limits"]),
       count=st.integers(1, 40), split=st.integers(0, 40),
       offset=arrays(float, 3, elements=st.floats(-0.03, 0.03)),
       compiled_tick=st.booleans())
def test_the_batched_measures_are_the_per_period_ones(scenario, count, split, offset,
                                                      compiled_tick):
    """Periods measured together (:meth:`TeleopLoop.measure_all_later`), in two batches
    split anywhere, give ``tick``'s records measured period by period, for targets moved
    by ``offset`` (the commands, the errors and the geometry's motion all drawn anew)."""
    plan = load_scenario(scenario)
    (at_once, _), (later, _) = (scenario_loop(scenario, compiled_tick, 0.001) for _ in range(2))
    targets = [moved_by(plan.target((i + 1) * LoopConfig().dt), offset) for i in range(count)]
    expected = [at_once.tick(target, lambda now: plan.update(now, at_once.constraints, at_once.q))
                for target in targets]
    periods = [later.tick_measured_later(target,
                                         lambda now: plan.update(now, later.constraints, later.q))
               for target in targets]
    records = later.measure_all_later(periods[:split]) + later.measure_all_later(periods[split:])
    assert len(records) == count
    for record, wanted in zip(records, expected):
        records_equal(record, wanted)


class StiffHole(Hole):
    """A user's hole with its own math: twice the hole's error (and its drift)."""

    def evaluate(self, placement: pin.SE3) -> ConstraintPoint:
        point = super().evaluate(placement)
        return ConstraintPoint(point.p, point.C, point.C_perp, 2.0 * point.error,
                               point.rhs - self.gain * point.error)

    def error(self, placement: pin.SE3) -> np.ndarray:
        return 2.0 * super().error(placement)


@pytest.mark.parametrize("compiled_tick", [True, False])
def test_a_subclass_with_its_own_math_is_measured_by_it_after_the_run(ur5_instrument,
                                                                      compiled_tick):
    """The hole's batched form is the hole's math: a subclass with its own is measured
    period by period, and the records equal ``tick``'s (with the hole's form its constraint
    error was half the true one)."""
    assert batched_form(StiffHole) is PER_PERIOD and batched_form(Hole) is not PER_PERIOD
    records = []
    for later in (False, True):
        hole = StiffHole.on_link(ur5_instrument, ur5_instrument.q_home, distance=0.2)
        loop = TeleopLoop(ur5_instrument, CJMController(ur5_instrument, [hole]),
                          compiled_tick=compiled_tick)
        target = loop.ee_placement() * pin.exp6(np.array([0.02, -0.01, 0.01, 0.0, 0.0, 0.1]))
        if later:
            records.append(loop.measure_all_later([loop.tick_measured_later(target)
                                                   for _ in range(30)]))
        else:
            records.append([loop.tick(target) for _ in range(30)])
    assert records[0][-1].constraint_error > 1e-6
    for record, wanted in zip(*reversed(records)):
        records_equal(record, wanted)
