"""The baselines recover and stay bounded: a hole that jumps 5.5 cm, the
8.2 s proxqp step, and the CJM's damping near a singularity (docs/design.md 10.6, 10.7)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from constraints import Constraint, Hole
from controllers import CJMController, QPController, StepStatus
from teleop import load_robot
from teleop.controller_specs import make_controller, spec_names
from teleop.loop import TeleopLoop

DATA = Path(__file__).parent / "data"

#: The jump of the issue's case (m), across the link axis.
JUMP = 0.055

#: "Back on the hole": the loop's explicit Euler step leaves a steady hole error of about
#: ``|a_c| dt / (2 K)`` (a_c the point's acceleration) once the rows are held: 5e-6 m at
#: 1 m/s^2, K = 100 1/s, dt = 1 ms. 1e-4 m is 20 times that and 1/550 of the jump.
BACK_ON_THE_HOLE = 1e-4


def jumped_hole_loop(robot, spec: str) -> tuple[TeleopLoop, pin.SE3]:
    """A loop holding the EE still with a hole 10 cm down the link, after the hole jumped."""
    hole = Hole.on_link(robot, robot.q_home, distance=0.1)
    # recovery, not timing: iteration caps only (the deadline is tested apart)
    controller = make_controller(spec, robot, [hole], time_budget=None)
    loop = TeleopLoop(robot, controller)
    target = loop.ee_placement()
    placement = loop.ee_placement()  # (refreshes loop.data)
    link = loop.data.oMf[robot.model.getFrameId(hole.link)]
    across = np.cross(link.rotation @ hole.link_axis, [0.0, 0.0, 1.0])
    hole.center = hole.center + JUMP * across / np.linalg.norm(across)
    assert placement is not None
    return loop, target


@pytest.mark.parametrize("spec", spec_names())
def test_every_controller_is_back_on_the_hole_within_half_a_second(sda10f, spec):
    loop, target = jumped_hole_loop(sda10f, spec)
    records = [loop.tick(target) for _ in range(500)]  # 0.5 s at 1 kHz
    errors = np.array([r.constraint_error for r in records])
    assert errors[0] > 0.04  # the jump is there
    failed = [(i, r.message) for i, r in enumerate(records) if r.failed]
    assert not failed, failed[:3]
    off = np.flatnonzero(errors > BACK_ON_THE_HOLE)
    back = int(off[-1]) + 1 if off.size else 0
    print(f"{spec}: back on the hole (< {BACK_ON_THE_HOLE:g} m) after {back} ms")
    assert back < 500, (spec, errors[-1])
    # the controller's degraded steps give the rows' residual; the loop's own (the hole
    # measured off at the sensed configuration, docs/design.md 5.2) the error in mm
    degraded = [r for r in records if r.status == StepStatus.CONSTRAINT_DEGRADED.value]
    assert degraded
    for record in degraded:
        if record.controller_status == StepStatus.CONSTRAINT_DEGRADED.value:
            assert "m/s" in record.message, record.message
        else:
            assert record.message.startswith("measured: ") and "mm off" in record.message


def slow_case(solver: str, time_budget=None) -> tuple[QPController, np.ndarray, np.ndarray]:
    case = json.loads((DATA / "proxqp-slow-case.json").read_text())
    robot = load_robot(case["robot"])
    controller = QPController(robot, [Constraint.from_dict(d) for d in case["cons_dicts"]],
                              solver=solver, time_budget=time_budget)
    return controller, np.array(case["q"]), np.array(case["twist"])


@pytest.mark.parametrize("solver", ["proxqp", "daqp", "osqp"])
def test_a_slow_step_is_bounded_finite_and_in_the_limits(solver):
    """The issue's 8.2 s proxqp step, bounded by the iteration caps alone (no deadline): a
    generous guard (1 s of CPU), which 8 s fails."""
    controller, q, twist = slow_case(solver)
    controller.solve(q, twist)  # first call: imports, allocations
    start = time.process_time()
    qd = controller.solve(q, twist)
    spent = time.process_time() - start
    print(f"{solver}: {spent * 1e3:.1f} ms CPU, {controller.info.status.value}")
    assert spent < 1.0
    assert np.all(np.isfinite(qd))
    lower, upper = controller.bounds(q)
    assert np.all(qd >= lower - 1e-9 * (1 + np.abs(lower)))
    assert np.all(qd <= upper + 1e-9 * (1 + np.abs(upper)))


def test_a_spent_budget_fails_the_step_with_the_reason_and_a_zero_command():
    controller, q, twist = slow_case("daqp")
    controller.settings["iter_limit"] = 1
    qd = controller.solve(q, twist)
    assert controller.info.status is StepStatus.FAILED
    assert "iteration limit" in controller.info.message
    np.testing.assert_array_equal(qd, 0.0)


@pytest.mark.parametrize("spec", ["qp:proxqp", "qp:daqp", "qp:osqp", "mink:proxqp", "mink:daqp"])
def test_a_spent_deadline_fails_the_step_with_the_reason_and_a_zero_command(sda10f, spec):
    hole = Hole.on_link(sda10f, sda10f.q_home, distance=0.1)
    controller = make_controller(spec, sda10f, [hole], time_budget=1e-9)  # spent at once
    qd = controller.solve(sda10f.q_home, np.full(6, 0.01))
    assert controller.info.status is StepStatus.FAILED
    assert "time budget" in controller.info.message or "time limit" in controller.info.message
    np.testing.assert_array_equal(qd, 0.0)


def test_the_default_deadline_is_ten_control_periods(sda10f):
    assert QPController(sda10f, dt=2e-3).budget.time_budget == pytest.approx(20e-3)
    assert QPController(sda10f, time_budget=None).budget.time_budget is None
    with pytest.raises(ValueError, match="time_budget"):
        QPController(sda10f, time_budget=-1.0)


# -- the CJM's damping ---------------------------------------------------------------------

REPRO_Q = np.array([-0.764, -0.812, -0.040, 1.486, -1.700, 0.083, -1.000, 0.598])
REPRO_TWIST = np.array([0.0426, -0.0249, 0.0815, -0.0073, -0.011, 0.0])

#: Stationarity tolerance of each backend's task stage (normalised units:
#: ``controllers.numerics.TOLERANCE_RANGE`` for proxqp and daqp, OSQP's ``eps_abs``).
STATIONARITY = {"proxqp": 1e-10, "daqp": 1e-10, "osqp": 1e-7}


@pytest.fixture(scope="module")
def scene_hole():
    scene = json.loads((DATA / "least-squares-scene.json").read_text())
    return Constraint.from_dict(scene["constraints"][0]["constraint"])


def damped_tolerance(robot, q, solver: str, damping: float, sigma_min: float) -> float:
    """A stationarity residual ``r`` leaves ``qd`` off by ``r s / curvature``, the task
    stage's curvature being at least ``max(lambda^2, sigma_min^2)`` (``s`` its scale)."""
    data = robot.model.createData()
    jacobian = pin.computeFrameJacobian(robot.model, data, q, robot.model.getFrameId(robot.ee_frame),
                                        pin.LOCAL)
    scale = float(np.vdot(jacobian, jacobian)) / 6
    return STATIONARITY[solver] * scale / max(damping**2, sigma_min**2) + 1e-12


@pytest.mark.parametrize("solver", ["proxqp", "daqp", "osqp"])
def test_the_qp_carries_the_cjms_damping_at_the_issues_configuration(sda10f, scene_hole, solver):
    cjm = CJMController(sda10f, [scene_hole], form="general", backend="python")
    qp = QPController(sda10f, [scene_hole], solver=solver, time_budget=None)  # numerics
    expected = cjm.solve(REPRO_Q, REPRO_TWIST)
    assert cjm.info.damping > 0.04  # a singularity: the CJM damps
    qd = qp.solve(REPRO_Q, REPRO_TWIST)
    assert qp.info.damping == pytest.approx(cjm.info.damping, rel=1e-9)
    tolerance = damped_tolerance(sda10f, REPRO_Q, solver, cjm.info.damping, cjm.info.sigma_min)
    assert np.max(np.abs(qd - expected)) <= tolerance
    assert np.max(np.abs(qd)) < 0.3  # not 2.95 rad/s on joints 2 and 4
    default = CJMController(sda10f, [scene_hole]).solve(REPRO_Q, REPRO_TWIST)
    np.testing.assert_allclose(qd, default, atol=tolerance)


@settings(max_examples=25, deadline=None,  # most draws bind a limit (assumed away)
          suppress_health_check=[HealthCheck.function_scoped_fixture,
                                 HealthCheck.filter_too_much])
@given(offset=st.lists(st.floats(-0.05, 0.05), min_size=8, max_size=8),
       twist=st.lists(st.floats(-0.1, 0.1), min_size=6, max_size=6),
       solver=st.sampled_from(["proxqp", "daqp"]))
def test_near_the_singularity_the_qp_equals_the_damped_cjm(sda10f, scene_hole, offset, twist,
                                                         solver):
    q = REPRO_Q + np.array(offset)
    twist = np.array(twist)
    cjm = CJMController(sda10f, [scene_hole], form="general", backend="python")
    expected = cjm.solve(q, twist)
    assume(cjm.info.method == "general")  # no limit binding (SNS is compared elsewhere)
    lower, upper = cjm.bounds(q)
    assume(np.all(expected > lower + 1e-6) and np.all(expected < upper - 1e-6))
    qp = QPController(sda10f, [scene_hole], solver=solver, time_budget=None)  # numerics
    qd = qp.solve(q, twist)
    tolerance = damped_tolerance(sda10f, q, solver, cjm.info.damping, cjm.info.sigma_min)
    assert np.max(np.abs(qd - expected)) <= tolerance, (cjm.info.damping, cjm.info.sigma_min)
