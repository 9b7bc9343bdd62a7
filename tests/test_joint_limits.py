"""Joint limits in the CJM (saturation in the null space) and the honesty of its step status.

Property-based (hypothesis) over both built-in robots, random configurations inside the
limits (some joints pushed to within 0..1e-2 rad of a limit), every constraint type up to
1 cm off its geometry and twists from 1e-3 to 1e3 in norm:

* every command of the CJM (default form and ``form="general"``) is finite, inside the
  velocity limits to ``limit (1 + 1e-9)``, inside ``controller.bounds(q)`` to the same
  tolerance, and ``q + qd dt`` stays inside the position limits;
* a step that says ``ok`` or ``scaled`` holds its rows to 1e-9 m/s, by its own report
  and by the rows this file recomputes from ``constraint.rows`` on fresh Pinocchio data;
  a step whose rows are broken says ``constraint_degraded`` (or ``failed``);
* where no limit binds, the CJM is the plain null-space solution written here with SciPy,
  and the unlimited controller's command, to 1e-12;
* with limits active, CJM and QP (daqp) both stay inside and hold the rows, and the QP's
  twist error is not larger than the CJM's (it is optimal for its cost; ``-s`` prints the
  ratio CJM error / QP error);
* conflicting constraints never report ``ok`` with a residual above 1e-9.

Tolerance on the box: ``1e-9 limit_i`` (the velocity limit of the joint), i.e. the
``|qd_i| <= limit_i (1 + 1e-9)`` of the velocity limits carried over to the position
bounds (a bound near zero has no meaningful relative tolerance of its own).

The QP backends' false infeasibilities once seen here, and the wording of a step held by
a limit, are regression tests in tests/test_joint_limit_regressions.py.
"""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
from conftest import HOLE_DISTANCE, kinematics
from hypothesis import HealthCheck, assume, event, example, given, settings
from hypothesis import note as hypothesis_note
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument
from hypothesis.extra.numpy import arrays

from constraints import Barrier, Hole, Plane, PointLock
from controllers import CJMController, QPController, StepStatus
from teleop import load_robot

#: residual (m/s) under which a row counts as held (the controllers' EQUALITY_TOLERANCE)
ROWS_HELD = 1e-9
#: relative tolerance on the joint limits
LIMIT_TOLERANCE = 1e-9
#: the statuses that promise every row held
ROWS_PROMISED = (StepStatus.OK, StepStatus.SCALED)
#: the statuses allowed when a row is not held
ROWS_BROKEN = (StepStatus.CONSTRAINT_DEGRADED, StepStatus.FAILED)
UNLIMITED = {"velocity_limits": False, "position_limits": False}
KINDS = ("hole", "plane", "lock", "barrier")
FORMS = ("auto", "general")

PROPERTY = settings(max_examples=200, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


def note(message: str) -> None:
    """``hypothesis.note`` inside a property, nothing in a plain test."""
    try:
        hypothesis_note(message)
    except InvalidArgument:
        pass


@functools.cache
def robot_named(name: str):
    return load_robot(name)


# ----------------------------------------------------------------------- strategies


@st.composite
def configurations(draw, robot, near_limits: float = 0.5) -> np.ndarray:
    """Uniform inside the position limits; with probability ``near_limits`` one to three
    joints at 0, 1e-12 .. 1e-2 rad from one of their limits."""
    model = robot.model
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    fractions = draw(arrays(float, model.nq, elements=st.floats(0.0, 1.0)))
    q = lower + fractions * (upper - lower)
    if draw(st.floats(0.0, 1.0)) < near_limits:
        joints = draw(st.lists(st.integers(0, model.nq - 1), min_size=1, max_size=3, unique=True))
        for joint in joints:
            gap = draw(st.sampled_from([0.0, 1e-12, 1e-9, 1e-6, 1e-4, 1e-3, 1e-2]))
            q[joint] = upper[joint] - gap if draw(st.booleans()) else lower[joint] + gap
    return np.clip(q, lower, upper)


@st.composite
def near_home(draw, robot, spread: float = 0.15) -> np.ndarray:
    """``q_home`` plus up to ``spread`` rad per joint (well inside the limits)."""
    model = robot.model
    q = robot.q_home + draw(arrays(float, model.nq, elements=st.floats(-spread, spread)))
    return np.clip(q, model.lowerPositionLimit + 0.05, model.upperPositionLimit - 0.05)


def units(n: int):
    """Unit vectors in R^n (a map, not a filter: a short draw becomes the first axis)."""
    def normalised(v: np.ndarray) -> np.ndarray:
        size = np.linalg.norm(v)
        return v / size if size > 0.1 else np.eye(n)[0]

    return arrays(float, n, elements=st.floats(-1.0, 1.0)).map(normalised)


unit3, unit6 = units(3), units(6)


def twists(low: float, high: float):
    """Twists ``[v; w]`` with a random direction and ``10^low <= |V| <= 10^high``."""
    return st.builds(lambda direction, exponent: direction * 10.0 ** exponent,
                     unit6, st.floats(low, high))


def offsets(largest: float = 0.01):
    """A displacement of at most ``largest`` m in a random direction."""
    return st.builds(lambda direction, size: size * direction, unit3, st.floats(0.0, largest))


@st.composite
def constraint_on(draw, robot, q, kind: str, largest_offset: float = 0.01):
    """A constraint of ``kind`` on the robot's constrained link at ``q``, then moved up to
    ``largest_offset`` m off (so its drift feedback is active)."""
    distance = HOLE_DISTANCE[robot.name]
    offset = draw(offsets(largest_offset))
    if kind == "hole":
        constraint = Hole.on_link(robot, q, distance=distance)
        constraint.move_to(constraint.center + offset)
    elif kind == "plane":
        constraint = Plane.through_link_point(robot, q, draw(unit3), distance=distance)
        constraint.move_to(constraint.plane_point + offset)
    elif kind == "lock":
        constraint = PointLock.on_link(robot, q, distance=distance)
        constraint.move_to(constraint.target + offset)
    else:
        constraint = Barrier.through_link_point(robot, q, draw(unit3), distance=distance)
        constraint.move_to(constraint.plane_point + offset)
    return constraint


@st.composite
def cases(draw, q_strategy=configurations, kinds=KINDS, largest_offset=0.01,
          twist_exponents=(-3.0, 3.0), at_most=2):
    """``(robot, q, constraints, twist)``: one or two constraints on the constrained link."""
    name = draw(st.sampled_from(sorted(HOLE_DISTANCE)))
    robot = robot_named(name)
    q = draw(q_strategy(robot))
    chosen = draw(st.lists(st.sampled_from(kinds), min_size=1, max_size=at_most))
    constraints = [draw(constraint_on(robot, q, kind, largest_offset)) for kind in chosen]
    twist = draw(twists(*twist_exponents))
    return name, q, constraints, twist


def unpack(case):
    """``(robot, q, constraints, twist)``, and the case noted in full for a failure report."""
    name, q, constraints, twist = case
    note(f"robot {name!r}\nq = {q.tolist()}\ntwist = {twist.tolist()}\n" + "\n".join(
        f"{type(c).__name__} {({k: v for k, v in vars(c).items() if not k.startswith('_')})}"
        for c in constraints))
    return robot_named(name), q, constraints, twist


# ------------------------------------------------------------------------ reference checks


def ee_jacobian(robot, data) -> np.ndarray:
    return pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(robot.ee_frame), pin.LOCAL)


def rows_of(robot, q, constraints):
    """``(A, b)`` of the equalities and ``(G, h)`` of the barriers (``G qd >= h``) at ``q``,
    from ``constraint.rows`` on fresh data (``computeJointJacobians`` + ``updateFramePlacements``)."""
    data = kinematics(robot, q)
    nv = robot.model.nv
    equalities = [c.rows(robot.model, data) for c in constraints if c.is_equality]
    barriers = [c.rows(robot.model, data) for c in constraints if not c.is_equality]

    def stack(blocks):
        if not blocks:
            return np.zeros((0, nv)), np.zeros(0)
        return np.vstack([A for A, _ in blocks]), np.concatenate([b for _, b in blocks])

    return stack(equalities), stack(barriers), data


def residuals(robot, q, constraints, qd) -> tuple[float, float]:
    """``max |A qd - b|`` over the equalities and ``max(b - G qd)`` over the barriers."""
    (A, b), (G, h), _ = rows_of(robot, q, constraints)
    equality = float(np.max(np.abs(A @ qd - b), initial=0.0))
    barrier = float(np.max(h - G @ qd, initial=0.0))
    return equality, barrier


def limit_violations(controller, q, qd) -> list[str]:
    """What is wrong with ``qd`` at ``q``: non-finite, ``|qd| > limit (1 + 1e-9)``, out of
    ``bounds(q)``, ``q + qd dt`` past a position limit (both to ``1e-9 limit``, in rad/s
    and rad/s x dt)."""
    model = controller.model
    if qd.shape != (model.nv,) or not np.all(np.isfinite(qd)):
        return [f"not a finite ({model.nv},) command: {qd}"]
    limit = controller.velocity_limit
    lower, upper = controller.bounds(q)
    tolerance = LIMIT_TOLERANCE * limit
    problems = []
    over = np.abs(qd) - limit - tolerance
    if np.any(over > 0.0):
        problems.append(f"velocity limit exceeded by {np.max(np.abs(qd) - limit):.3e} rad/s")
    if np.any(qd > upper + tolerance) or np.any(qd < lower - tolerance):
        problems.append(f"outside the box by {max(np.max(qd - upper), np.max(lower - qd)):.3e} rad/s")
    after = q + qd * controller.dt
    past = np.maximum(after - model.upperPositionLimit, model.lowerPositionLimit - after)
    if np.any(past > tolerance * controller.dt):
        problems.append(f"q + qd dt past a position limit by {np.max(past):.3e} rad")
    return problems


def assert_inside_the_limits(controller, q, qd) -> None:
    problems = limit_violations(controller, q, qd)
    assert not problems, f"{problems}: status {controller.info.status.value}, qd {qd.tolist()}"


def assert_status_is_honest(controller, robot, q, constraints, qd) -> tuple[float, float]:
    """``ok``/``scaled`` hold every row (reported and recomputed); broken rows are
    reported as ``constraint_degraded`` (or ``failed``). Returns the two residuals."""
    info = controller.info
    equality, barrier = residuals(robot, q, constraints, qd)
    broken = max(equality, barrier)
    note(f"{info.status.value} residual {equality:.3e} barrier {barrier:.3e} "
         f"info.residual {info.equality_residual:.3e} scale {info.scale} {info.message!r}")
    assert info.success == (info.status is not StepStatus.FAILED)
    if info.status in ROWS_PROMISED:
        assert info.equality_residual <= ROWS_HELD
        assert equality <= ROWS_HELD
        assert barrier <= ROWS_HELD
    if broken > ROWS_HELD:
        assert info.status in ROWS_BROKEN, (info.status, broken, info.message)
    return equality, barrier


def null_space_reference(robot, q, constraints, twist, posture_gain, posture) -> np.ndarray:
    """Rows ``A qd = b`` first, then the twist by least squares over ``null(A)``, then
    the posture task ``posture_gain * (posture - q)`` projected into ``null([A; J])``.
    SciPy and NumPy only: no project code beyond ``constraint.rows``."""
    (A, b), _, data = rows_of(robot, q, [c for c in constraints if c.is_equality])
    J = ee_jacobian(robot, data)
    qd = np.linalg.pinv(A) @ b if A.shape[0] else np.zeros(robot.model.nv)
    N = scipy.linalg.null_space(A) if A.shape[0] else np.eye(robot.model.nv)
    y = np.linalg.lstsq(J @ N, twist - J @ qd, rcond=None)[0]
    qd = qd + N @ y
    if posture_gain:
        redundancy = scipy.linalg.null_space(np.vstack([A, J]))
        posture_velocity = posture_gain * pin.difference(robot.model, q, posture)
        qd = qd + redundancy @ (redundancy.T @ posture_velocity)
    return qd


# ------------------------------------------------------------------------ the properties


@PROPERTY
@given(case=cases())
def test_every_cjm_command_is_inside_the_limits_and_its_status_is_honest(case):
    robot, q, constraints, twist = unpack(case)
    for form in FORMS:
        controller = CJMController(robot, constraints, form=form)
        qd = controller.solve(q, twist)
        event(f"{form}: {controller.info.status.value}")
        assert_inside_the_limits(controller, q, qd)
        assert_status_is_honest(controller, robot, q, constraints, qd)


@PROPERTY
@given(case=cases(twist_exponents=(-3.0, 3.0), at_most=1),
       posture_gain=st.sampled_from([0.0, 1.0]))
def test_one_constraint_near_a_limit_with_posture_off_and_on(case, posture_gain):
    """The saturation path with and without the posture task, a single constraint (the
    analytical form where it applies)."""
    robot, q, constraints, twist = unpack(case)
    for form in FORMS:
        controller = CJMController(robot, constraints, form=form, posture_gain=posture_gain)
        qd = controller.solve(q, twist)
        assert_inside_the_limits(controller, q, qd)
        assert_status_is_honest(controller, robot, q, constraints, qd)


@pytest.mark.slow
@PROPERTY
@given(case=cases(q_strategy=near_home, kinds=("hole", "plane", "lock"), largest_offset=1e-3,
                  twist_exponents=(-3.0, -1.0)),
       posture_gain=st.sampled_from([0.0, 1.0]))
def test_where_no_limit_binds_the_cjm_is_the_plain_null_space_solution(case, posture_gain):
    """The Python step (the reference implementation, LAPACK's SVDs) against SciPy's
    null-space solution, to 1e-12. The compiled step's algebra (QR and Jacobi SVDs) rounds
    otherwise, which two nearly parallel rows amplify by their condition number: 3.5e-12
    rad/s from SciPy's, 1.5e-12 from the Python step's, for two planes 0.2 degree apart on
    one link (condition number 225); tests/test_compiled_step.py holds it to this step."""
    robot, q, constraints, twist = unpack(case)
    (A, _), _, data = rows_of(robot, q, constraints)
    sigma = np.linalg.svd(A, compute_uv=False)
    assume(sigma[-1] > 1e-6 * sigma[0])  # independent rows: the solution is well posed
    redundant = scipy.linalg.null_space(np.vstack([A, ee_jacobian(robot, data)])).shape[1] > 0
    for form in FORMS:
        unlimited = CJMController(robot, constraints, form=form, posture_gain=posture_gain,
                                  backend="python", **UNLIMITED)
        free = unlimited.solve(q, twist)
        controller = CJMController(robot, constraints, form=form, posture_gain=posture_gain,
                                   backend="python")
        lower, upper = controller.bounds(q)
        margin = 0.1 * controller.velocity_limit  # well inside the box
        assume(np.all(free < upper - margin) and np.all(free > lower + margin))
        assume(unlimited.info.damping == 0.0)  # the reference is undamped
        qd = controller.solve(q, twist)
        np.testing.assert_allclose(qd, free, rtol=0.0, atol=1e-12)
        assert controller.info.saturated_joints == () and controller.info.scale == 1.0
        assert controller.info.method in ("analytical", "general")
        assert_status_is_honest(controller, robot, q, constraints, qd)
        # The analytical form with a plane (Jbar 6 x 7) resolves its one redundant
        # direction as the minimum norm of [u; w; qd_post], without the posture task:
        # there the reference (posture in null([A; J])) is not its solution.
        if form == "general" or not redundant or len(constraints) > 1:
            reference = null_space_reference(robot, q, constraints, twist, posture_gain,
                                             controller.posture)
            np.testing.assert_allclose(qd, reference, rtol=0.0, atol=1e-12)


def twist_error(robot, q, qd, twist) -> float:
    return float(np.linalg.norm(ee_jacobian(robot, kinematics(robot, q)) @ qd - twist))


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(case=cases(q_strategy=functools.partial(configurations, near_limits=0.8),
                  kinds=("hole", "plane", "lock", "barrier"), twist_exponents=(-1.0, 1.0)))
# Hypothesis 6.170.17's draw: every joint at a limit, the plane's row nearly joint 0's
# bound (daqp said infeasible; tests/test_joint_limit_regressions.py, docs/design.md 10.2)
@example(case=("ur5_instrument", np.array([2 * np.pi] + [-2 * np.pi] * 5 + [-1.4, -1.4]),
               [Plane("instrument_shaft", [0.0, 0.0, 0.2], [-0.81725, -0.39145, -0.005491],
                      [1.19e-7, 1.0, 0.0], gain=100.0)],
               np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])))
def test_with_limits_active_cjm_and_qp_stay_inside_and_the_qp_tracks_no_worse(case):
    robot, q, constraints, twist = unpack(case)
    cjm = CJMController(robot, constraints)
    qd_cjm = cjm.solve(q, twist)
    assume(cjm.info.method == "saturated")  # a limit binds
    assert_inside_the_limits(cjm, q, qd_cjm)
    assert_status_is_honest(cjm, robot, q, constraints, qd_cjm)
    equality, barrier = residuals(robot, q, constraints, qd_cjm)
    assume(max(equality, barrier) <= ROWS_HELD)  # the CJM's command is feasible for the QP
    # undamped: the bound below is the optimality of |J qd - V|^2 alone (the default QP
    # also carries the CJM's damping |D qd|^2, docs/design.md 10.7)
    qp = QPController(robot, constraints, solver="daqp", singular_threshold=0.0)
    qd_qp = qp.solve(q, twist)
    assert_inside_the_limits(qp, q, qd_qp)
    if not qp.info.success:
        # should a backend still declare a feasible problem infeasible, the fallback
        # must be honest: zero, and said so
        event("qp failed")
        assert qp.info.status is StepStatus.FAILED and not np.any(qd_qp), qp.info
        return
    assert_status_is_honest(qp, robot, q, constraints, qd_qp)
    assert max(residuals(robot, q, constraints, qd_qp)) <= ROWS_HELD
    error_cjm, error_qp = twist_error(robot, q, qd_cjm, twist), twist_error(robot, q, qd_qp, twist)
    print(f"{robot.name} {cjm.info.status.value:>13}  |V| {np.linalg.norm(twist):8.3g}  "
          f"CJM error / QP error = {error_cjm / max(error_qp, 1e-300):.6g}")
    # the QP minimises |J qd - V|^2 + mu |qd|^2 over a set holding the CJM's command:
    # |J qd_qp - V|^2 <= |J qd_cjm - V|^2 + mu (|qd_cjm|^2 - |qd_qp|^2)
    tikhonov = qp.mu * max(0.0, float(qd_cjm @ qd_cjm - qd_qp @ qd_qp))
    assert error_qp <= np.sqrt(error_cjm**2 + tikhonov) + 1e-9, (error_qp, error_cjm)


# ---------------------------------------------------------------------- the issue's repro


@pytest.mark.parametrize("form", FORMS)
def test_issue_plane_moved_one_centimetre_under_a_still_twist(form):
    r = load_robot("sda10f")
    q = r.q_home.copy()
    p = Plane.through_link_point(r, q, [0, 0, 1], distance=0.08)
    p.move_to(p.plane_point + [0, 0, 0.01])
    controller = CJMController(r, [p], form=form)
    qd = controller.solve(q, np.zeros(6))
    assert_inside_the_limits(controller, q, qd)
    assert np.all(np.abs(qd) <= controller.velocity_limit)
    equality, _ = assert_status_is_honest(controller, r, q, [p], qd)  # not ok unless held
    if controller.info.status is StepStatus.OK:
        assert equality <= ROWS_HELD and twist_error(r, q, qd, np.zeros(6)) <= 1e-6
    qp = QPController(r, [p], solver="daqp")
    qd_qp = qp.solve(q, np.zeros(6))
    assert_inside_the_limits(qp, q, qd_qp)
    assert twist_error(r, q, qd_qp, np.zeros(6)) <= twist_error(r, q, qd, np.zeros(6)) + 1e-9


# ------------------------------------------------------------------ conflicting constraints


def two_locks(robot, q, gap, direction):
    first = PointLock.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    second = PointLock.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    second.move_to(second.target + gap * direction)
    return [first, second]


def across_the_link(robot, q, direction):
    """The part of ``direction`` (world) across the constrained link's axis at ``q``."""
    placement = kinematics(robot, q).oMf[robot.model.getFrameId(robot.constrained_link)]
    axis = placement.rotation @ robot.link_axis
    return direction - (direction @ axis) * axis


def hole_and_lock(robot, q, lock_distance, offset):
    """A hole moved by ``offset`` across the link, and a lock on the link at ``q``."""
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    hole.move_to(hole.center + across_the_link(robot, q, offset))
    return [hole, PointLock.on_link(robot, q, distance=lock_distance)]


@pytest.mark.parametrize("gap", [1e-9, 1e-2])
@pytest.mark.parametrize("name", sorted(HOLE_DISTANCE))
def test_two_point_locks_apart_are_never_ok(name, gap):
    robot = robot_named(name)
    q = robot.q_home.copy()
    constraints = two_locks(robot, q, gap, np.array([0.6, 0.0, 0.8]))
    for twist in (np.zeros(6), np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02]), np.full(6, 50.0)):
        for form in FORMS:
            controller = CJMController(robot, constraints, form=form)
            qd = controller.solve(q, twist)
            assert_inside_the_limits(controller, q, qd)
            equality, _ = assert_status_is_honest(controller, robot, q, constraints, qd)
            assert equality > ROWS_HELD  # the rows conflict: a residual of K gap / 2 at least
            assert controller.info.status in ROWS_BROKEN


@PROPERTY
@given(name=st.sampled_from(sorted(HOLE_DISTANCE)), data=st.data(),
       gap_exponent=st.floats(-12.0, -2.0), direction=unit3, twist=twists(-3.0, 3.0),
       same_point=st.booleans(), lock_distance=st.floats(-0.1, 0.3))
def test_conflicting_constraints_never_report_ok_with_a_residual(name, data, gap_exponent,
                                                                 direction, twist, same_point,
                                                                 lock_distance):
    robot = robot_named(name)
    q = data.draw(configurations(robot), label="q")
    if data.draw(st.booleans(), label="two locks"):
        constraints = two_locks(robot, q, 10.0 ** gap_exponent, direction)
    else:
        distance = HOLE_DISTANCE[name] if same_point else lock_distance
        constraints = hole_and_lock(robot, q, distance, 10.0 ** gap_exponent * direction)
    for form in FORMS:
        controller = CJMController(robot, constraints, form=form)
        qd = controller.solve(q, twist)
        assert_inside_the_limits(controller, q, qd)
        equality, _ = assert_status_is_honest(controller, robot, q, constraints, qd)
        if equality > ROWS_HELD:
            assert controller.info.status is not StepStatus.OK


@pytest.mark.parametrize("name", sorted(HOLE_DISTANCE))
def test_hole_and_lock_at_the_hole_point_one_centimetre_apart_are_degraded(name):
    robot = robot_named(name)
    q = robot.q_home.copy()
    offset = across_the_link(robot, q, np.array([1.0, 0.3, -0.2]))
    constraints = hole_and_lock(robot, q, HOLE_DISTANCE[name], 0.01 * offset / np.linalg.norm(offset))
    for form in FORMS:
        controller = CJMController(robot, constraints, form=form)
        qd = controller.solve(q, np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02]))
        assert_inside_the_limits(controller, q, qd)
        equality, _ = assert_status_is_honest(controller, robot, q, constraints, qd)
        assert equality > ROWS_HELD and controller.info.status is StepStatus.CONSTRAINT_DEGRADED
