"""CJM and QP on the built-in robots: constraint held, twist tracked, solutions agree."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
from conftest import HOLE_DISTANCE, ee_jacobian, kinematics, near_home

from constraints import Barrier, Hole, Plane
from controllers import CJMController, QPController

EXACT = dict(singular_threshold=0.0, velocity_limits=False, position_limits=False)  # undamped, unscaled CJM


def reference_hole_rows(robot, q, hole):
    """Hole rows written from scratch: Pinocchio Jacobian + geometry, no project code."""
    model = robot.model
    data = kinematics(robot, q)
    frame = model.getFrameId(hole.link)
    placement = data.oMf[frame]
    axis = np.asarray(hole.link_axis)
    center_local = placement.rotation.T @ (hole.center - placement.translation)
    p = (axis @ center_local) * axis  # point of the axis nearest the centre
    C = scipy.linalg.null_space(axis[None, :]).T  # any basis across the axis
    lateral_error = C @ (p - center_local)
    J = pin.getFrameJacobian(model, data, frame, pin.LOCAL)
    A = C @ (J[:3] - pin.skew(p) @ J[3:])
    return A, -hole.gain * lateral_error


def reference_nullspace_solution(robot, q, A, b, twist):
    """min |J qd - V| s.t. A qd = b through SciPy's null space and least squares."""
    J = ee_jacobian(robot, q)
    qd0 = np.linalg.lstsq(A, b, rcond=None)[0]
    N = scipy.linalg.null_space(A)
    y = np.linalg.lstsq(J @ N, twist - J @ qd0, rcond=None)[0]
    return qd0 + N @ y


def offset_hole(robot, q, rng, offset=1e-3):
    """A hole on the link, then pushed ``offset`` m sideways so the drift term is active."""
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    sideways = np.cross(rng.normal(size=3), hole.center)
    hole.move_to(hole.center + offset * sideways / np.linalg.norm(sideways))
    return hole


def test_snippet_from_the_readme():
    from teleop import load_robot

    robot = load_robot("sda10f")
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.08)
    twist = np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02])
    qd_cjm = CJMController(robot, [hole]).solve(q, twist)
    qd_qp = QPController(robot, [hole], solver="proxqp").solve(q, twist)
    np.testing.assert_allclose(qd_cjm, qd_qp, atol=1e-6)


def test_sda10f_hole_on_link_6_splits_six_before_two_after(sda10f):
    q = sda10f.q_home.copy()
    hole = Hole.on_link(sda10f, q, distance=0.08)
    controller = CJMController(sda10f, [hole])
    split = controller.split(sda10f.model.getFrameId("arm_link_5_r"))
    assert split.pre.tolist() == [0, 1, 2, 3, 4, 5]
    assert split.post.tolist() == [6, 7]
    assert controller.constrained_jacobian(q).shape == (6, 6)
    controller.solve(q, np.zeros(6))
    assert controller.info.method == "analytical"


@pytest.mark.parametrize("seed", range(5))
def test_cjm_holds_the_hole_and_tracks_the_twist(robot, seed):
    rng = np.random.default_rng(seed)
    q = near_home(robot, rng)
    hole = offset_hole(robot, q, rng)
    twist = rng.normal(size=6) * 0.02
    controller = CJMController(robot, [hole], **EXACT)
    qd = controller.solve(q, twist)
    assert controller.info.method == "analytical" and controller.info.success
    A, b = reference_hole_rows(robot, q, hole)
    assert np.abs(b).max() > 1e-3  # the drift term is exercised
    assert np.max(np.abs(A @ qd - b)) <= 1e-12
    assert np.linalg.cond(controller.constrained_jacobian(q)) < 1e4  # Jbar non-singular
    np.testing.assert_allclose(ee_jacobian(robot, q) @ qd, twist, atol=1e-10)
    np.testing.assert_allclose(qd, reference_nullspace_solution(robot, q, A, b, twist), atol=1e-9)


@pytest.mark.parametrize("seed", range(5))
def test_general_and_paper_forms_give_the_same_joint_velocities(robot, seed):
    rng = np.random.default_rng(100 + seed)
    q = near_home(robot, rng)
    hole = offset_hole(robot, q, rng)
    twist = rng.normal(size=6) * 0.02
    reference = CJMController(robot, [hole], **EXACT).solve(q, twist)
    paper = CJMController(robot, [hole], parametrisation="paper", **EXACT)
    general = CJMController(robot, [hole], form="general", **EXACT)
    np.testing.assert_allclose(paper.solve(q, twist), reference, atol=1e-9)
    np.testing.assert_allclose(general.solve(q, twist), reference, atol=1e-9)
    assert paper.info.method == "analytical" and general.info.method == "general"


def test_nullspace_form_stays_finite_at_a_zero_where_the_paper_form_breaks(robot):
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.0)
    twist = np.array([0.01, 0.0, -0.01, 0.02, 0.01, 0.0])
    controller = CJMController(robot, [hole], **EXACT)
    qd = controller.solve(q, twist)
    assert np.all(np.isfinite(qd)) and controller.info.method == "analytical"
    assert np.linalg.cond(controller.constrained_jacobian(q)) < 1e3
    A, b = reference_hole_rows(robot, q, hole)
    assert np.max(np.abs(A @ qd - b)) <= 1e-12
    with pytest.raises(ValueError, match="a = 0"):
        CJMController(robot, [hole], parametrisation="paper").constrained_jacobian(q)
    # approaching a = 0 the paper's CJM degrades, ours does not
    near = Hole.on_link(robot, q, distance=1e-5)
    paper_cond = np.linalg.cond(CJMController(robot, [near], parametrisation="paper").constrained_jacobian(q))
    ours_cond = np.linalg.cond(CJMController(robot, [near]).constrained_jacobian(q))
    assert paper_cond > 1e3 * ours_cond


@pytest.mark.parametrize("solver", ["proxqp", "daqp"])
@pytest.mark.parametrize("seed", range(4))
def test_cjm_and_qp_agree_when_no_inequality_is_active(robot, solver, seed):
    rng = np.random.default_rng(200 + seed)
    q = near_home(robot, rng)
    hole = offset_hole(robot, q, rng)
    twist = rng.normal(size=6) * 0.01
    qd_cjm = CJMController(robot, [hole], **EXACT).solve(q, twist)
    qp = QPController(robot, [hole], solver=solver)
    qd_qp = qp.solve(q, twist)
    lower, upper = qp.bounds(q)
    assert np.all(qd_qp > lower + 1e-6) and np.all(qd_qp < upper - 1e-6)  # no bound active
    assert qp.info.success and qp.info.equality_residual <= 1e-9
    np.testing.assert_allclose(qd_qp, qd_cjm, atol=1e-6)


def test_osqp_is_close_and_reports_its_residual(robot):
    rng = np.random.default_rng(7)
    q = near_home(robot, rng)
    hole = offset_hole(robot, q, rng)
    twist = rng.normal(size=6) * 0.01
    qd_cjm = CJMController(robot, [hole], **EXACT).solve(q, twist)
    qp = QPController(robot, [hole], solver="osqp")
    qd = qp.solve(q, twist)
    A, b = reference_hole_rows(robot, q, hole)
    assert qp.info.success
    assert qp.info.equality_residual == pytest.approx(np.max(np.abs(A @ qd - b)), abs=1e-12)
    assert qp.info.equality_residual <= 1e-6
    np.testing.assert_allclose(qd, qd_cjm, atol=1e-3)


def test_two_constraints_general_cjm_and_qp_agree(sda10f):
    """Hole on link 6 plus a plane through a point of link 3 (an earlier link)."""
    robot = sda10f
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.08)
    plane = Plane.through_link_point(robot, q, normal=[0.0, 0.6, 0.8],
                                     link_point=[0.0, 0.1, -0.02], link="arm_link_3_e")
    twist = np.array([0.01, -0.005, 0.008, 0.02, -0.01, 0.015])
    controller = CJMController(robot, [hole, plane], **EXACT)
    qd = controller.solve(q, twist)
    assert controller.info.method == "general"
    A_hole, b_hole = reference_hole_rows(robot, q, hole)
    A_plane, b_plane = plane.rows(robot.model, kinematics(robot, q))
    A, b = np.vstack([A_hole, A_plane]), np.concatenate([b_hole, b_plane])
    assert np.max(np.abs(A @ qd - b)) <= 1e-12
    np.testing.assert_allclose(qd, reference_nullspace_solution(robot, q, A, b, twist), atol=1e-9)
    for solver in ("proxqp", "daqp"):
        np.testing.assert_allclose(QPController(robot, [hole, plane], solver=solver).solve(q, twist),
                                   qd, atol=1e-6)


def test_near_singular_jbar_stays_bounded_and_holds_the_constraint(sda10f):
    """Joint B at 0 lines joint T up with the link axis: Jbar is singular there."""
    robot = sda10f
    q = robot.q_home.copy()
    q[6] = 1e-4
    hole = Hole.on_link(robot, q, distance=0.08)
    sigma = np.linalg.svd(CJMController(robot, [hole]).constrained_jacobian(q), compute_uv=False)
    assert sigma[-1] < 1e-3  # really near singular
    # the direction the singular Jbar cannot produce, at operator speed
    u, _, _ = np.linalg.svd(CJMController(robot, [hole]).constrained_jacobian(q))
    twist = 0.05 * u[:, -1]
    undamped = CJMController(robot, [hole], **EXACT).solve(q, twist)
    damped = CJMController(robot, [hole], velocity_limits=False, position_limits=False)
    qd = damped.solve(q, twist)
    assert np.abs(undamped).max() > 20.0  # the exact inverse explodes
    assert np.abs(qd).max() < 2.0  # DLS keeps it bounded
    assert damped.info.damping > 0.0
    A, b = reference_hole_rows(robot, q, hole)
    assert np.max(np.abs(A @ qd - b)) <= 1e-12  # and the hole still holds exactly


def test_velocity_limits_slow_the_task_and_keep_the_constraint(ur5_instrument):
    """An over-fast twist: the twist's part is scaled, the hole (with drift) still holds."""
    robot = ur5_instrument
    rng = np.random.default_rng(5)
    q = robot.q_home.copy()
    hole = offset_hole(robot, q, rng)  # drift term active: b != 0
    twist = np.array([2.0, -1.0, 1.5, 3.0, 2.0, -1.0])
    raw = CJMController(robot, [hole], velocity_limits=False, position_limits=False).solve(q, twist)
    drift_only = CJMController(robot, [hole], velocity_limits=False,
                               position_limits=False).solve(q, np.zeros(6))
    controller = CJMController(robot, [hole])
    qd = controller.solve(q, twist)
    assert 0.0 < controller.info.scale < 1.0
    np.testing.assert_allclose(qd, drift_only + controller.info.scale * (raw - drift_only), atol=1e-12)
    assert np.all(np.abs(qd) <= robot.model.velocityLimit + 1e-12)
    assert np.isclose(np.max(np.abs(qd) / robot.model.velocityLimit), 1.0)  # as fast as allowed
    A, b = reference_hole_rows(robot, q, hole)
    assert np.abs(b).max() > 1e-3
    assert np.max(np.abs(A @ qd - b)) <= 1e-12


def test_barrier_is_held_by_both_controllers_when_pushed(ur5_instrument):
    """The tip pushes down against a barrier just below it: both stop at the boundary."""
    robot = ur5_instrument
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.2)
    data = kinematics(robot, q)
    tip = data.oMf[robot.model.getFrameId("tool_tip")].translation
    barrier = Barrier("tool_tip", [0.0, 0.0, 0.0], tip - [0.0, 0.0, 2e-4], [0.0, 0.0, 1.0])
    placement_tip = data.oMf[robot.model.getFrameId("tool_tip")]
    down_in_tip = placement_tip.rotation.T @ np.array([0.0, 0.0, -0.05])
    twist = np.concatenate([down_in_tip, [0.0, 0.0, 0.0]])
    cjm = CJMController(robot, [hole, barrier], **EXACT)
    qd_cjm = cjm.solve(q, twist)
    assert cjm.info.active_barriers == (1,)
    A_b, b_b = barrier.rows(robot.model, data)
    assert A_b @ qd_cjm == pytest.approx(b_b, abs=1e-12)  # on the boundary: -K d
    for solver in ("proxqp", "daqp"):
        qp = QPController(robot, [hole, barrier], solver=solver)
        np.testing.assert_allclose(qp.solve(q, twist), qd_cjm, atol=1e-6)
        assert qp.info.active_barriers == (1,)
    # pulled away from the barrier, it is inactive and the twist is tracked exactly
    away = CJMController(robot, [hole, barrier], **EXACT)
    qd_away = away.solve(q, -twist)
    assert away.info.active_barriers == ()
    np.testing.assert_allclose(ee_jacobian(robot, q) @ qd_away, -twist, atol=1e-10)


def test_moving_hole_is_followed_through_the_feed_forward(ur5_instrument):
    """A hole moving sideways at 5 mm/s: the link point moves with it, to first order."""
    robot = ur5_instrument
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.2)
    hole.move_to(hole.center, velocity=[0.005, -0.003, 0.001])
    twist = np.array([0.0, 0.01, 0.0, 0.0, 0.02, 0.0])
    for controller in (CJMController(robot, [hole], **EXACT), QPController(robot, [hole])):
        qd = controller.solve(q, twist)
        dt = 1e-6
        q_next = pin.integrate(robot.model, q, qd * dt)
        hole_next = Hole(hole.link, hole.center + dt * hole.velocity, link_axis=hole.link_axis)
        placement = kinematics(robot, q_next).oMf[robot.model.getFrameId(hole.link)]
        assert np.max(np.abs(hole_next.error(placement))) < 1e-6 * dt * 1e3  # O(dt^2)


@pytest.mark.parametrize("posture_gain", [0.0, 1.0, 5.0])
def test_a_wide_cjm_spends_its_null_space_as_the_general_form(sda10f, posture_gain):
    """A plane on link 6 leaves Jbar 6 x 7: the analytical form's spare direction goes to
    the posture (or the minimum-norm qd) exactly as the general form's does."""
    rng = np.random.default_rng(11)
    for _ in range(5):
        q = near_home(sda10f, rng, 0.1)
        twist = rng.normal(scale=0.02, size=6)
        plane = Plane.through_link_point(sda10f, q, normal=[0.0, 0.0, 1.0], distance=0.08)
        options = dict(posture_gain=posture_gain, singular_threshold=0.0,
                       velocity_limits=False, position_limits=False)
        analytical = CJMController(sda10f, [plane], **options)
        general = CJMController(sda10f, [plane], form="general", **options)
        qd = analytical.solve(q, twist)
        assert analytical.info.method == "analytical"
        np.testing.assert_allclose(qd, general.solve(q, twist), atol=1e-12)
        np.testing.assert_allclose(ee_jacobian(sda10f, q) @ qd, twist, atol=1e-12)
