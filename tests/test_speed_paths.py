"""The fast paths of the controllers give what the slow paths (and fresh solves) give.

Covers what the speed work added: the analytical CJM's LU fast path and its SVD fallback,
the Hole's closed-form (affine) terms and rows, cheap input checks, buffers that must not
leak between steps, the persistent proxqp object and the direct daqp call. No wall-clock
assertions: timing is ``teleop bench``'s job.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import qpsolvers
import scipy.linalg
from conftest import HOLE_DISTANCE, ee_jacobian, kinematics, near_home
from hypothesis import given, settings
from hypothesis import strategies as st
from strategies import placements, unit3, vec3

import controllers.cjm.analytical as analytical_module
from constraints import Barrier, Hole, Plane, PointLock
from controllers import CJMController, QPController, damped_least_squares, nullspace
from controllers.base import Kinematics
from controllers.cjm.affine_forms import affine_form_of, affine_inputs
from controllers.cjm.analytical import AffineTerms, terms_size, terms_views, write_terms
from controllers.linalg import DampingPolicy

EXACT = dict(singular_threshold=0.0, velocity_limits=False, position_limits=False)

def force_svd_path(monkeypatch) -> None:
    """No certified bound can pass an infinite floor: every square Jbar goes to the SVD."""
    monkeypatch.setattr(analytical_module, "FAST_PATH_MIN_SIGMA", np.inf)


# ------------------------------------------------------------------ the Hole's closed forms


@settings(max_examples=200, deadline=None)
@given(center=vec3, axis=unit3, velocity=vec3, gain=st.floats(0.0, 200.0),
       placement=placements(), moving=st.booleans())
def test_hole_affine_terms_equal_the_generic_terms(center, axis, velocity, gain, placement, moving):
    hole = Hole("link", center, link_axis=axis, gain=gain,
                velocity=velocity if moving else (0.0, 0.0, 0.0))
    fast, generic = np.empty(terms_size(2)), np.empty(terms_size(2))
    form = affine_form_of(hole)
    AffineTerms(hole, form).write(*affine_inputs(form, hole, placement), fast)
    state = hole.evaluate(placement)
    write_terms(state, hole.structure(placement), generic)  # evaluate + structure
    # the two round differently: a few ulps of the geometry, times the gain in the terms
    # holding gain x error (up to 2.7e-12 at gain 191 and |center| 1.2)
    magnitude = 1.0 + np.linalg.norm(center) + np.linalg.norm(velocity)
    tolerance = max(1e-12, 1e-14 * (1.0 + gain) * magnitude)
    np.testing.assert_allclose(fast, generic, atol=tolerance)
    B, R = terms_views(fast, 2)
    np.testing.assert_allclose(R[:, 1:] @ B[:, 1:], 0.0, atol=tolerance)  # C v_c = 0 on S
    np.testing.assert_allclose(R[:, 1:] @ B[:, 0], state.rhs, atol=tolerance)  # V_a0 gives b


def test_hole_rows_equal_the_generic_rows(robot):
    rng = np.random.default_rng(1)
    q = near_home(robot, rng)
    data = kinematics(robot, q)
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    hole.move_to(hole.center + [1e-3, -2e-3, 5e-4], velocity=[0.003, 0.001, -0.002])
    frame = robot.model.getFrameId(hole.link)
    placement = data.oMf[frame]
    J_a = pin.getFrameJacobian(robot.model, data, frame, pin.LOCAL)
    for _ in range(2):  # moving, then still
        A, b = hole.rows(robot.model, data)
        state = hole.evaluate(placement)
        point_jacobian = J_a[:3] - pin.skew(state.p) @ J_a[3:]
        np.testing.assert_allclose(A, state.C @ point_jacobian, atol=1e-13)
        hole_local = placement.actInv(hole.center)
        lateral = hole_local - (hole.link_axis @ hole_local) * hole.link_axis
        velocity = placement.rotation.T @ hole.velocity
        np.testing.assert_allclose(b, state.C @ (hole.gain * lateral + velocity), atol=1e-12)
        hole.move_to(hole.center)


#: where a user's hole reads its centre, off the true one in its link's frame (m)
SHIFT = np.array([1e-3, 2e-3, 0.0])


class ShiftedHole(Hole):
    """A user's hole with its own ``evaluate``: its centre read :data:`SHIFT` off in the
    link's frame."""

    def evaluate(self, placement: pin.SE3):
        return self.evaluate_local(placement.actInv(self.center) + SHIFT, None)

    def error(self, placement: pin.SE3) -> np.ndarray:
        return self.evaluate(placement).error


@pytest.mark.parametrize("backend", ["python", "compiled"])
def test_a_subclass_with_its_own_evaluate_is_held_by_it(ur5_instrument, backend):
    """No affine form for a subclass with its own math: its command is the one for a plain
    hole whose centre is where the subclass reads it (the hole's affine form evaluated it
    as a plain hole at its own centre, ignoring its evaluate: both backends' commands
    1.57 rad/s off this one)."""
    robot, q = ur5_instrument, ur5_instrument.q_home
    shifted = ShiftedHole.on_link(robot, q, distance=0.2)
    assert affine_form_of(shifted) is None
    data = kinematics(robot, q)
    placement = data.oMf[robot.model.getFrameId(shifted.link)]
    plain = Hole(shifted.link, placement.act(placement.actInv(shifted.center) + SHIFT),
                 link_axis=shifted.link_axis, gain=shifted.gain)
    twist = np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0])
    expected = CJMController(robot, [plain], backend="python").solve(q, twist)
    actual = CJMController(robot, [shifted], backend=backend).solve(q, twist)
    np.testing.assert_allclose(actual, expected, rtol=0.0, atol=1e-9)


def test_changing_the_gain_after_a_solve_is_seen(sda10f):
    q = near_home(sda10f, np.random.default_rng(2))
    hole = Hole.on_link(sda10f, q, distance=0.08)
    hole.move_to(hole.center + [0.0, 1e-3, 0.0])
    twist = np.array([0.01, 0.0, -0.01, 0.02, 0.01, 0.0])
    controller = CJMController(sda10f, [hole], **EXACT)
    controller.solve(q, twist)
    hole.gain = 20.0
    fresh = CJMController(sda10f, [Hole(hole.link, hole.center, hole.link_axis, gain=20.0)], **EXACT)
    np.testing.assert_allclose(controller.solve(q, twist), fresh.solve(q, twist), atol=1e-14)


# ------------------------------------------------------------- the analytical CJM's paths


@pytest.mark.parametrize("seed", range(4))
def test_lu_fast_path_and_svd_path_give_the_same_joint_velocities(robot, seed, monkeypatch):
    rng = np.random.default_rng(300 + seed)
    q = near_home(robot, rng, spread=0.05)
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    hole.move_to(hole.center + 1e-3 * rng.normal(size=3))
    twist = rng.normal(size=6) * 0.02
    # DLS would act < 0.01; the Python reference, whose module constant the SVD path forces
    # (the compiled step's LU and SVD paths are held to it in test_compiled_step.py)
    policy = dict(singular_threshold=0.01, velocity_limits=False, position_limits=False,
                  backend="python")
    fast = CJMController(robot, [hole], **policy)
    qd_fast = fast.solve(q, twist)
    sigma = np.linalg.svd(fast.constrained_jacobian(q), compute_uv=False)[-1]
    assert sigma > np.sqrt(6) * fast.policy.threshold  # well conditioned: the fast path
    assert fast.info.method == "analytical" and fast.info.damping == 0.0
    assert sigma / np.sqrt(6) - 1e-12 <= fast.info.sigma_min <= sigma + 1e-12  # the bound
    assert fast.info.sigma_min != pytest.approx(sigma, rel=1e-9)  # so it really was the bound

    force_svd_path(monkeypatch)
    slow = CJMController(robot, [hole], **policy)
    qd_slow = slow.solve(q, twist)
    assert slow.info.sigma_min == pytest.approx(sigma, rel=1e-9)  # the SVD's own value
    np.testing.assert_allclose(qd_fast, qd_slow, rtol=0.0, atol=1e-12)
    assert fast.info.equality_residual <= 1e-12 and slow.info.equality_residual <= 1e-12


def test_near_singular_jbar_falls_back_to_the_svd_dls(sda10f, monkeypatch):
    """Joint B at 1e-4 rad: sigma_min(Jbar) < 1e-3, the damping acts, the SVD decides."""
    q = sda10f.q_home.copy()
    q[6] = 1e-4
    hole = Hole.on_link(sda10f, q, distance=0.08)
    controller = CJMController(sda10f, [hole], velocity_limits=False, position_limits=False)
    jbar = controller.constrained_jacobian(q)
    sigma = np.linalg.svd(jbar, compute_uv=False)
    u = np.linalg.svd(jbar)[0]
    twist = 0.05 * u[:, -1]
    qd = controller.solve(q, twist)
    assert controller.info.sigma_min == pytest.approx(sigma[-1], rel=1e-6)  # exact, not a bound
    assert controller.info.damping == pytest.approx(
        np.sqrt(controller.policy.lambda_squared(sigma[-1])), rel=1e-6)
    assert controller.info.damping > 0.0 and np.abs(qd).max() < 2.0
    # same answer as the SVD path taken on purpose
    force_svd_path(monkeypatch)
    np.testing.assert_allclose(
        CJMController(sda10f, [hole], velocity_limits=False, position_limits=False).solve(q, twist), qd,
        atol=1e-12)


def test_constant_damping_always_takes_the_svd_path(sda10f):
    q = sda10f.q_home.copy()
    hole = Hole.on_link(sda10f, q, distance=0.08)
    controller = CJMController(sda10f, [hole], damping=1e-3, velocity_limits=False, position_limits=False)
    controller.solve(q, np.array([0.01, 0.0, 0.0, 0.0, 0.02, 0.0]))
    sigma = np.linalg.svd(controller.constrained_jacobian(q), compute_uv=False)[-1]
    assert controller.info.sigma_min == pytest.approx(sigma, rel=1e-9)
    assert controller.info.damping == pytest.approx(1e-3)


def test_singular_pre_chain_hands_over_to_the_general_form(sda10f):
    """Joint U at 0 stretches the arm: J_a (6 x 6) is singular, the general form takes over."""
    q = sda10f.q_home.copy()
    q[4] = 0.0
    hole = Hole.on_link(sda10f, q, distance=0.08)
    data = kinematics(sda10f, q)
    J_a = pin.getFrameJacobian(sda10f.model, data, sda10f.model.getFrameId(hole.link), pin.LOCAL)
    assert np.linalg.svd(J_a[:, :6], compute_uv=False)[-1] < 1e-4
    controller = CJMController(sda10f, [hole])
    qd = controller.solve(q, np.array([0.01, 0.0, 0.0, 0.0, 0.02, 0.0]))
    assert controller.info.method == "general" and "pre-constraint" in controller.info.message
    assert np.all(np.isfinite(qd))


def test_plane_and_point_lock_use_the_generic_terms_in_the_analytical_form(sda10f):
    """Constraints without an affine form go through evaluate + write_terms."""
    q = sda10f.q_home.copy()
    twist = np.array([0.02, 0.01, -0.01, 0.05, -0.02, 0.03])
    lock = PointLock.on_link(sda10f, q, distance=0.08)
    plane = Plane.through_link_point(sda10f, q, normal=[0.0, 0.0, 1.0], distance=0.08)
    for constraint in (lock, plane):
        analytical = CJMController(sda10f, [constraint], **EXACT)
        general = CJMController(sda10f, [constraint], form="general", **EXACT)
        qd = analytical.solve(q, twist)
        assert analytical.info.method == "analytical"
        J = ee_jacobian(sda10f, q)
        np.testing.assert_allclose(J @ qd, J @ general.solve(q, twist), atol=1e-9)
        A, b = constraint.rows(sda10f.model, kinematics(sda10f, q))
        assert np.max(np.abs(A @ qd - b)) <= 1e-12


def test_steps_do_not_share_buffers(sda10f):
    """Each solve returns its own array: the next step must not overwrite the last."""
    hole = Hole.on_link(sda10f, sda10f.q_home, distance=0.08)
    rng = np.random.default_rng(4)
    for controller in (CJMController(sda10f, [hole]), QPController(sda10f, [hole], solver="daqp"),
                       QPController(sda10f, [hole], solver="proxqp")):
        q1, q2 = near_home(sda10f, rng, 0.05), near_home(sda10f, rng, 0.05)
        first = controller.solve(q1, np.full(6, 0.01))
        kept = first.copy()
        info = controller.info
        second = controller.solve(q2, np.full(6, -0.01))
        assert second is not first and controller.info is not info
        np.testing.assert_array_equal(first, kept)


def test_new_constraints_give_the_same_result_as_a_new_controller(sda10f):
    q = near_home(sda10f, np.random.default_rng(5), 0.05)
    twist = np.array([0.01, -0.01, 0.0, 0.02, 0.0, -0.01])
    first = Hole.on_link(sda10f, q, distance=0.08)
    second = Hole.on_link(sda10f, q, distance=0.02)
    controller = CJMController(sda10f, [first], **EXACT)
    controller.solve(q, twist)
    controller.set_constraints([second])
    np.testing.assert_allclose(controller.solve(q, twist),
                               CJMController(sda10f, [second], **EXACT).solve(q, twist), atol=1e-14)


# -------------------------------------------------------------------------- input checks


def test_huge_but_finite_input_is_not_called_non_finite(sda10f):
    hole = Hole.on_link(sda10f, sda10f.q_home, distance=0.08)
    controller = CJMController(sda10f, [hole])
    with np.errstate(all="ignore"):
        qd = controller.solve(sda10f.q_home, np.array([1e308, 1e308, 0.0, 0.0, 0.0, 0.0]))
    assert np.all(np.isfinite(qd))  # a flagged zero or a scaled command, never a ValueError
    with pytest.raises(ValueError, match="twist must be finite"):
        controller.solve(sda10f.q_home, np.array([1e308, np.nan, 0.0, 0.0, 0.0, 0.0]))
    with pytest.raises(ValueError, match="q must be finite"):
        controller.solve(np.full(8, np.inf), np.zeros(6))
    with pytest.raises(ValueError, match=r"twist must have shape \(6,\)"):
        controller.solve(sda10f.q_home, [0.0] * 7)
    np.testing.assert_array_equal(  # lists are fine
        controller.solve(sda10f.q_home.tolist(), [0.0] * 6), controller.solve(sda10f.q_home, np.zeros(6)))


def test_kinematics_placement_is_read_on_demand(sda10f):
    hole = Hole.on_link(sda10f, sda10f.q_home, distance=0.08)
    controller = CJMController(sda10f, [hole])
    q = near_home(sda10f, np.random.default_rng(6))
    kin = controller._kinematics(q)
    assert isinstance(kin, Kinematics)
    reference = kinematics(sda10f, q).oMf[controller.ee_frame_id]
    assert kin.ee_placement.isApprox(reference, 1e-12)
    np.testing.assert_allclose(kin.ee_jacobian, ee_jacobian(sda10f, q), atol=1e-14)


# --------------------------------------------------------------------- shared linear algebra


def test_nullspace_and_dls_against_scipy():
    rng = np.random.default_rng(7)
    for m, n in ((2, 8), (3, 8), (6, 6), (0, 5)):
        A = rng.normal(size=(m, n))
        N, pinv, rank = nullspace(A)
        assert rank == m and N.shape == (n, n - m)
        if m:
            reference = scipy.linalg.null_space(A)
            np.testing.assert_allclose(N @ N.T, reference @ reference.T, atol=1e-12)
            np.testing.assert_allclose(pinv, np.linalg.pinv(A), atol=1e-12)
    J = rng.normal(size=(6, 6))
    solution = damped_least_squares(J, np.ones(6), DampingPolicy())
    np.testing.assert_allclose(solution.x, np.linalg.solve(J, np.ones(6)), atol=1e-10)
    assert solution.sigma_min == pytest.approx(np.linalg.svd(J, compute_uv=False)[-1])


# ------------------------------------------------------------------------------- the QPs


def reference_bounds(controller: QPController, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The joint box as the first implementation wrote it, element by element."""
    model = controller.model
    lower, upper = np.full(model.nv, -np.inf), np.full(model.nv, np.inf)
    limit = np.full(model.nv, np.inf)
    if controller.joint_bounds.velocity_limits:
        limit = np.asarray(model.velocityLimit, dtype=float)
        limit = np.where(np.isfinite(limit) & (limit > 0), limit, np.inf)
        lower, upper = -limit, limit.copy()
    if controller.joint_bounds.position_limits:
        scale = controller.joint_bounds.limit_gain / controller.dt
        for j in range(1, model.njoints):
            if model.nqs[j] == 1 and model.nvs[j] == 1:
                iq, iv = model.idx_qs[j], model.idx_vs[j]
                lo, hi = model.lowerPositionLimit[iq], model.upperPositionLimit[iq]
                if np.isfinite(lo) and np.isfinite(hi) and hi > lo:
                    lower[iv] = max(lower[iv], scale * (lo - q[iq]))
                    upper[iv] = min(upper[iv], scale * (hi - q[iq]))
    # past a limit: come back, never faster than the velocity limit
    lower, upper = np.minimum(lower, limit), np.maximum(upper, -limit)
    return lower, np.maximum(upper, lower)


@pytest.mark.parametrize("options", [{}, {"velocity_limits": False}, {"position_limits": False},
                                     {"dt": 0.01, "limit_gain": 0.5}])
def test_bounds_match_the_element_by_element_definition(sda10f, options):
    controller = QPController(sda10f, [], **options)
    rng = np.random.default_rng(8)
    model = sda10f.model
    for _ in range(20):  # inside, near and past the position limits
        q = rng.uniform(model.lowerPositionLimit - 0.01, model.upperPositionLimit + 0.01)
        for got, want in zip(controller.bounds(q), reference_bounds(controller, q)):
            np.testing.assert_array_equal(got, want)


def barrier_below_the_tip(robot, q):
    data = kinematics(robot, q)
    tip = data.oMf[robot.model.getFrameId(robot.ee_frame)].translation
    return Barrier(robot.ee_frame, [0.0, 0.0, 0.0], tip - [0.0, 0.0, 2e-4], [0.0, 0.0, 1.0])


def qp_sequence(robot, controller_or_none, steps=50, seed=9):
    """A closed-loop run that changes q every step, adds a barrier at 15, drops it at 35.

    Yields ``(q, twist, constraints)``; the caller solves and the run integrates ``qd``.
    """
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    barrier = barrier_below_the_tip(robot, q)
    ee = robot.model.getFrameId(robot.ee_frame)
    rng = np.random.default_rng(seed)
    for k in range(steps):
        constraints = [hole, barrier] if 15 <= k < 35 else [hole]
        rotation = kinematics(robot, q).oMf[ee].rotation
        push = rotation.T @ np.array([0.0, 0.0, -0.05]) if 15 <= k < 35 else rng.normal(size=3) * 0.03
        twist = np.concatenate([push, 0.05 * np.array([np.sin(k / 5), np.cos(k / 7), 0.3])])
        qd = yield q, twist, constraints
        q = pin.integrate(robot.model, q, qd * 1e-2)


def fresh_qpsolvers_solution(robot, controller, q, twist, constraints, solver, **settings):
    """The same QP, built from scratch with public calls and solved by a fresh qpsolvers
    call, and the condition number of its Hessian.

    With 8 joints and at least 8 rows (a hole and the task) the lexicographic QP is its
    task stage alone, ``min |J qd - V|^2 / s + |A qd - b|^2`` under the rows and the
    limits (``s = |J|_F^2 / 6``; the second term is constant on the feasible set), whose
    Hessian ``H`` is positive definite.
    """
    model = robot.model
    data = kinematics(robot, q)
    J = ee_jacobian(robot, q)
    rows = [c.rows(model, data) for c in constraints if c.is_equality]
    A, b = np.vstack([r[0] for r in rows]), np.concatenate([r[1] for r in rows])
    inequalities = [c.rows(model, data) for c in constraints if not c.is_equality]
    G = -np.vstack([r[0] for r in inequalities]) if inequalities else None
    h = -np.concatenate([r[1] for r in inequalities]) if inequalities else None
    lb, ub = controller.bounds(q)
    assert controller.priorities == "lexicographic"
    assert np.linalg.matrix_rank(np.vstack([A, J])) == model.nv  # no posture stage
    scale = np.sum(J * J) / 6.0
    hessian = J.T @ J / scale + A.T @ A
    solution = qpsolvers.solve_qp(hessian, -J.T @ twist / scale - A.T @ b, G, h, A, b, lb, ub,
                                  solver=solver, **settings)
    return solution, float(np.linalg.cond(hessian))


#: two exact (active-set) solves of one QP differ by about ``eps cond(H) |qd|``: this
#: factor of it (measured: at most 0.13 on these runs, where ``cond(H)`` is about 1.5e4)
ROUNDING_OF_THE_QP = 1.0


@pytest.mark.parametrize("solver, settings, tolerance", [
    # the fresh reference as tight as the controller, whose eps_abs follows the curvature
    ("proxqp", {"eps_abs": 1e-12, "eps_rel": 0.0}, 1e-8),
    # daqp is exact up to rounding: the bound comes from the Hessian's conditioning
    ("daqp", {"primal_tol": 1e-10}, None),
])
def test_persistent_qp_agrees_with_fresh_solves_while_constraints_come_and_go(
        robot, solver, settings, tolerance):
    controller = QPController(robot, solver=solver)
    run = qp_sequence(robot, controller)
    q, twist, constraints = next(run)
    barrier_held = 0
    try:
        while True:
            if constraints != controller.constraints:
                controller.set_constraints(constraints)
            qd = controller.solve(q, twist)
            assert controller.info.success, controller.info.message
            assert controller.info.equality_residual <= 1e-9
            reference, condition = fresh_qpsolvers_solution(robot, controller, q, twist,
                                                            constraints, solver, **settings)
            rounding = (ROUNDING_OF_THE_QP * np.finfo(float).eps * condition
                        * (1.0 + np.abs(reference).max()))
            np.testing.assert_allclose(qd, reference, rtol=0.0,
                                       atol=rounding if tolerance is None else tolerance)
            barrier_held += bool(controller.info.active_barriers)
            q, twist, constraints = run.send(qd)
    except StopIteration:
        pass
    assert barrier_held > 5  # the barrier really was pushed against


def test_proxqp_warm_start_changes_results_only_within_solver_accuracy(robot):
    """Warm starting proxqp from the previous result is an option (not the default)."""
    default = QPController(robot, solver="proxqp")
    warm = QPController(robot, solver="proxqp",
                        solver_settings={"initial_guess": "WARM_START_WITH_PREVIOUS_RESULT"})
    exact = QPController(robot, solver="daqp", solver_settings={"primal_tol": 1e-12})
    run = qp_sequence(robot, None)
    q, twist, constraints = next(run)
    try:
        while True:
            for controller in (default, warm, exact):
                if constraints != controller.constraints:
                    controller.set_constraints(constraints)
            qd = default.solve(q, twist)
            qd_warm = warm.solve(q, twist)
            qd_exact = exact.solve(q, twist)
            assert default.info.success and warm.info.success
            # proxqp at eps_abs 1e-10 is ~1e-7 from the active-set solution on these
            # problems (mu = 1e-10 leaves directions nearly flat); both starts stay there
            np.testing.assert_allclose(qd_warm, qd_exact, atol=1e-6)
            np.testing.assert_allclose(qd, qd_exact, atol=1e-6)
            np.testing.assert_allclose(qd_warm, qd, atol=1e-6)
            assert warm.info.equality_residual <= 1e-9
            q, twist, constraints = run.send(qd)
    except StopIteration:
        pass


def test_settings_the_direct_calls_cannot_take_go_through_qpsolvers(sda10f):
    q = sda10f.q_home.copy()
    hole = Hole.on_link(sda10f, q, distance=0.08)
    twist = np.array([0.01, -0.005, 0.008, 0.02, -0.01, 0.015])
    direct = QPController(sda10f, [hole], solver="proxqp")
    through = QPController(sda10f, [hole], solver="proxqp", solver_settings={"backend": "dense"})
    assert direct._proxqp is not None and through._proxqp is None
    np.testing.assert_allclose(direct.solve(q, twist), through.solve(q, twist), atol=1e-8)
    with pytest.raises(ValueError, match="initial_guess"):
        QPController(sda10f, [hole], solver="proxqp", solver_settings={"initial_guess": "guess"})
    daqp_direct = QPController(sda10f, [hole], solver="daqp")
    daqp_through = QPController(sda10f, [hole], solver="daqp", solver_settings={"verbose": False})
    assert daqp_direct._direct_daqp and not daqp_through._direct_daqp
    np.testing.assert_allclose(daqp_direct.solve(q, twist), daqp_through.solve(q, twist), atol=1e-12)


def test_proxqp_recovers_after_a_failed_step(sda10f, monkeypatch):
    """A failed solve drops the persistent object; the next feasible step solves. (The
    conflicting locks alone no longer fail, docs/design.md 10.7: the solves of that step
    are capped at one iteration, the last solve on a fresh object too.)"""
    from controllers.numerics import PROXQP_RHO, TASK_ACCURACY
    from controllers.optimization import proxqp as proxqp_backend

    monkeypatch.setattr(proxqp_backend, "PROXQP_FALLBACK_ITERATIONS", 1)
    # the flat stage's solve with the first rho (PROXQP_FLAT_RHO times the tolerance,
    # TASK_ACCURACY times the curvature), not the tolerance-sized one that finishes it
    monkeypatch.setattr(proxqp_backend, "PROXQP_FLAT_RHO", PROXQP_RHO / TASK_ACCURACY)
    q = sda10f.q_home.copy()
    lock = PointLock.on_link(sda10f, q, distance=0.05)
    other = PointLock(lock.link, lock.link_point, lock.target + [0.01, 0.0, 0.0])
    controller = QPController(sda10f, [lock], solver="proxqp")
    assert controller.solve(q, np.zeros(6)) is not None and controller.info.success
    controller.set_constraints([lock, other])
    caps = controller._proxqp.settings["max_iter"]
    controller._proxqp.settings["max_iter"] = 1  # for the objects this step creates
    controller.solve(q, np.zeros(6))
    assert not controller.info.success and "proxqp" in controller.info.message
    assert not controller._proxqp.solvers  # dropped
    controller._proxqp.settings["max_iter"] = caps
    controller.set_constraints([lock])
    qd = controller.solve(q, np.full(6, 0.001))
    assert controller.info.success and controller.info.equality_residual <= 1e-9
    np.testing.assert_allclose(
        qd, QPController(sda10f, [lock], solver="proxqp").solve(q, np.full(6, 0.001)), atol=1e-8)
