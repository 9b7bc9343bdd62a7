"""Collision rows in the CJM (docs/design.md section 18.4), both backends.

The velocity damper ``rows qd >= lower`` of every pair closer than the detection
distance is held by the step's active set after the barriers and below the equality
rows: a pair at the safety distance does not close, two arms pushed into each other stop
there with both trocars held, a pair the equality rows cannot keep apart is held by least
squares below them (constraint_degraded, named), and the compiled step agrees with the
Python one. The references are computed here: the rows measured again on a fresh
``pin.Data``, the true distance over every pair, the two-level least-squares solution
written with NumPy.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from constraints import Hole, PointLock
from constraints.collision import CollisionAvoidance, HalfSpace, Sphere
from controllers import CJMController, StepStatus
from controllers.cjm.report import Event
from teleop.robots import load_robot
from test_compiled_step import assert_same_report

BACKENDS = ("compiled", "python")
#: the twist's translations only: through a trocar an instrument's tip cannot also keep
#: its orientation, and the arms are pushed together by their tips' positions
TRANSLATION = [1.0, 1.0, 1.0, 0.0, 0.0, 0.0] * 2
#: how closely the compiled step's distances (m) agree with coal's (the Python step's)
DISTANCE_AGREEMENT = 1e-9
#: the issue's bound on every distance (m): the safety distance less 0.5 mm
MARGIN = 0.5e-3
SETTINGS = settings(max_examples=25, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def dual():
    return load_robot("sda10f_dual")


def tips(robot, q: np.ndarray) -> list[pin.SE3]:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return [data.oMf[robot.model.getFrameId(frame)] for frame in robot.ee_frames]


def push_together(robot, q: np.ndarray, speed: float) -> np.ndarray:
    """The stacked LOCAL twist moving the two tool tips towards each other at ``speed``."""
    left, right = tips(robot, q)
    towards = (right.translation - left.translation) / np.linalg.norm(right.translation - left.translation)
    twist = np.zeros(12)
    twist[:3] = left.rotation.T @ (speed * towards)
    twist[6:9] = right.rotation.T @ (-speed * towards)
    return twist


def drive(robot, q: np.ndarray, steps: int, dt: float = 0.01, speed: float = 0.05) -> np.ndarray:
    """``q`` after ``steps`` steps of the tips pushed together with no avoidance."""
    free = CJMController(robot, dt=dt, backend="python", twist_weight=TRANSLATION)
    for _ in range(steps):
        q = pin.integrate(robot.model, q, free.solve(q, push_together(robot, q, speed)) * dt)
    return q


@pytest.fixture(scope="module")
def apart(dual):
    """The tools' links about 2 cm apart, moving towards each other."""
    return drive(dual, dual.q_home.copy(), 185)


@pytest.fixture(scope="module")
def touching(dual, apart):
    """The tools' links closer than the safety distance (about 2 mm)."""
    collisions = CollisionAvoidance(dual)
    q = apart
    while collisions.minimum_distance(q)[0] > 0.002:
        q = drive(dual, q, 5)
    return q


def holes_at(robot, q: np.ndarray) -> list[Hole]:
    return [Hole.on_link(robot, q, distance=0.1, link=link, link_axis=robot.link_axes[link])
            for link in robot.constrained_links]


def hole_errors(robot, holes, q: np.ndarray) -> list[float]:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return [hole.violation(data.oMf[robot.model.getFrameId(hole.link)]) for hole in holes]


def rows_at(collisions: CollisionAvoidance, model: pin.Model, q: np.ndarray):
    """The avoidance rows at ``q``, measured on a fresh ``pin.Data``."""
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    return collisions.rows(model, data)


# -- a pair at the safety distance -------------------------------------------------------

def floor_at_safety_distance(robot, q: np.ndarray, tilt: np.ndarray) -> CollisionAvoidance:
    """Avoidance with a half-space under the left tool, moved so that the nearest link is
    exactly the safety distance above it (a distance to a plane is affine in its offset)."""
    normal = np.array([tilt[0], tilt[1], 1.0]) / np.linalg.norm([tilt[0], tilt[1], 1.0])
    centre = tips(robot, q)[0].translation - 0.1 * normal
    probe = CollisionAvoidance(robot, [HalfSpace(centre, normal, name="floor")], self_collision=False)
    distance, _ = probe.minimum_distance(q)
    floor = HalfSpace(centre + (distance - probe.safety_distance) * normal, normal, name="floor")
    return CollisionAvoidance(robot, [floor])


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), backend=st.sampled_from(BACKENDS),
       trocars=st.booleans(), speed=st.sampled_from([0.01, 0.1, 0.5]))
def test_a_pair_at_the_safety_distance_does_not_close(dual, seed, backend, trocars, speed):
    rng = np.random.default_rng(seed)
    q = pin.integrate(dual.model, dual.q_home, rng.uniform(-0.1, 0.1, dual.model.nv))
    collisions = floor_at_safety_distance(dual, q, rng.uniform(-0.3, 0.3, 2))
    distance, pair = collisions.minimum_distance(q)
    assert distance == pytest.approx(collisions.safety_distance, abs=1e-9)
    controller = CJMController(dual, holes_at(dual, q) if trocars else [], backend=backend,
                               collisions=collisions)
    left, right = tips(dual, q)
    twist = np.concatenate([left.rotation.T @ [0.0, 0.0, -speed], [0.0, 0.0, 0.0],
                            right.rotation.T @ rng.normal(size=3) * speed, [0.0, 0.0, 0.0]])
    qd = controller.solve(q, twist)
    rows = rows_at(collisions, dual.model, q)
    at_safety = rows.pairs.index(pair)
    assert rows.lower[at_safety] == pytest.approx(0.0, abs=1e-7)
    # every row's first-order distance rate at or above the damper's bound
    assert np.all(rows.rows @ qd >= rows.lower - 1e-9), (rows.rows @ qd - rows.lower, controller.info)
    info = controller.info
    if info.status is StepStatus.CONSTRAINT_DEGRADED:  # only where the joint box cannot
        # take the rows held (a fast push with the trocars: their correction scaled)
        assert Event.ROWS_SCALED in [event for event, *_ in controller.report.events], info
    assert info.minimum_distance == pytest.approx(distance, abs=1e-9)
    assert info.closest_pair == pair
    if pair in info.active_pairs and info.status is not StepStatus.OK:
        assert pair in info.message


# -- two arms pushed into each other -----------------------------------------------------

@pytest.mark.parametrize("backend", BACKENDS)
def test_arms_pushed_into_each_other_stop_at_the_safety_distance_with_the_trocars_held(
        dual, apart, backend):
    dt = 1e-3  # at 1 kHz and 1 cm/s the trocars' first-order error stays below 1 um
    collisions = CollisionAvoidance(dual)
    holes = holes_at(dual, apart)
    controller = CJMController(dual, holes, dt=dt, backend=backend, collisions=collisions,
                               twist_weight=TRANSLATION)
    q = apart.copy()
    floor = collisions.safety_distance - MARGIN
    for step in range(1500):
        qd = controller.solve(q, push_together(dual, q, 0.01))
        q = pin.integrate(dual.model, q, qd * dt)
        assert controller.info.minimum_distance >= floor, (step, controller.info)
        assert max(hole_errors(dual, holes, q)) <= 1e-6, (step, controller.info)
        if step % 250 == 249:
            assert collisions.minimum_distance(q)[0] >= floor, step
    distance, pair = collisions.minimum_distance(q)
    assert floor <= distance <= collisions.safety_distance + 1e-3  # pushed all the way
    info = controller.info
    assert info.status is StepStatus.LEAST_SQUARES, info
    assert pair in info.active_pairs
    assert f"held back by collision pair {pair}" in info.message
    left, right = pair.split(" | ")
    assert left.startswith("arm_left") and right.startswith("arm_right")


# -- the two backends --------------------------------------------------------------------

def collision_rounding_bound(controller: CJMController, q: np.ndarray) -> float:
    """tests/test_cjm_backends_fuzz.py's ``2 m n eps kappa`` with the collision rows the
    step held among its rows: ``kappa`` of the held rows times that of the task over
    their null space, the latter undamped. A pair's row is nearly a combination of the
    two tips' translations, so holding it leaves the task a singular value near the rank
    cut (1e-7 where the pair's witness points are near the tips): the damping keeps the
    task's solution well conditioned, but the posture is projected on the complement of
    the task's singular vectors, which two SVDs give ``eps sigma_max / sigma_min`` apart."""
    model = controller.model
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    report = controller.report
    held = [c.rows(model, data, f)[0] for c, f in zip(controller.constraints, controller.constraint_frames)
            if c.is_equality]
    held += [report.collision.rows[list(report.active_pairs)]] if report.active_pairs else []
    setup = controller.setup
    stacked = np.vstack([pin.getFrameJacobian(model, data, f, pin.LOCAL) for f in controller.ee_frame_ids])
    jacobian = setup.task_scale[:, None] * stacked[setup.task_entries]
    kappa, null_basis = 1.0, np.eye(model.nv)
    if held:
        _, s, vt = np.linalg.svd(np.vstack(held))
        kept = s > 1e-10 * max(1.0, s[0])
        kappa, null_basis = s[0] / s[kept][-1], vt[int(kept.sum()):].T
    s = np.linalg.svd(jacobian @ null_basis, compute_uv=False)
    kept = s > 1e-10 * max(1.0, s[0])
    rows = setup.task_rows + sum(len(h) for h in held)
    return 2.0 * rows * model.nv * np.finfo(float).eps * kappa * s[0] / s[kept][-1]


@pytest.fixture(scope="module")
def backend_pairs(dual, apart):
    """Per trocar setting, a Python and a compiled controller sharing one avoidance."""
    collisions = CollisionAvoidance(dual)
    pairs = {}
    for trocars in (False, True):
        holes = holes_at(dual, apart) if trocars else []
        pairs[trocars] = tuple(CJMController(dual, holes, backend=backend, collisions=collisions,
                                             twist_weight=TRANSLATION) for backend in ("python", "compiled"))
    return pairs


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), trocars=st.booleans(),
       approach=st.floats(0.0, 1.0), speed=st.sampled_from([1e-3, 0.05, 1.0]))
def test_the_compiled_step_equals_the_python_step_with_collision_rows(
        dual, apart, touching, backend_pairs, seed, trocars, approach, speed):
    rng = np.random.default_rng(seed)
    between = pin.interpolate(dual.model, apart, touching, approach)
    q = pin.integrate(dual.model, between, rng.uniform(-0.01, 0.01, dual.model.nv))
    twist = push_together(dual, q, speed) + rng.normal(size=12) * 0.2 * speed
    python, compiled = backend_pairs[trocars]
    expected, actual = python.solve(q, twist), compiled.solve(q, twist)
    bound = collision_rounding_bound(python, q) * (1.0 + float(np.max(np.abs(expected))))
    assert float(np.max(np.abs(actual - expected))) <= bound, (python.info, compiled.info)
    a, b = python.info, compiled.info
    assert (b.status, b.active_pairs, b.closest_pair) == (a.status, a.active_pairs, a.closest_pair)
    # the compiled step measures the distances itself (docs/design.md 18.4): coal's to
    # rounding for capsules, to its GJK tolerance (1e-10, 1e-9 m here) with a box
    assert math.isclose(b.minimum_distance, a.minimum_distance, rel_tol=0.0, abs_tol=DISTANCE_AGREEMENT)
    assert b.message == a.message
    assert_same_report(python.report, compiled.report)


# -- a pair the equality rows cannot keep apart ------------------------------------------

def pseudo_inverse(matrix: np.ndarray) -> np.ndarray:
    """``matrix^+`` with singular values at or below ``1e-10 max(1, sigma_max)`` taken as
    zero (the rank rule of controllers/linalg.py, absolute for small matrices: the
    collision row left in the null space of the locks is rounding, about 1e-12)."""
    u, s, vt = np.linalg.svd(matrix, full_matrices=False)
    kept = s > 1e-10 * max(1.0, s[0] if s.size else 0.0)
    return vt[kept].T @ (u[:, kept].T / s[kept, None])


def locks_at_witnesses(robot, collisions: CollisionAvoidance, q: np.ndarray):
    """Point locks holding the closest pair's two witness points still, and that pair."""
    rows = rows_at(collisions, robot.model, q)
    index = rows.pairs.index(rows.closest_pair)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    locks = []
    for link, point in zip(rows.closest_pair.split(" | "), rows.witnesses[index]):
        placement = data.oMf[robot.model.getFrameId(link)]
        locks.append(PointLock(link, placement.actInv(point), point))
    return locks, rows.closest_pair


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_pair_the_equality_rows_cannot_keep_apart_is_degraded_and_named(dual, touching, backend):
    collisions = CollisionAvoidance(dual)
    locks, pair = locks_at_witnesses(dual, collisions, touching)
    constraints = [*holes_at(dual, touching), *locks]
    controller = CJMController(dual, constraints, backend=backend, collisions=collisions,
                               twist_weight=TRANSLATION)
    qd = controller.solve(touching, push_together(dual, touching, 0.05))
    info = controller.info
    assert info.status is StepStatus.CONSTRAINT_DEGRADED, info
    assert pair in info.active_pairs
    assert f"collision pair {pair}" in info.message and "cannot be kept apart" in info.message
    # the equality rows (trocars and locks) held exactly
    model = dual.model
    data = model.createData()
    pin.computeJointJacobians(model, data, touching)
    pin.updateFramePlacements(model, data)
    blocks = [c.rows(model, data, f) for c, f in zip(controller.constraints, controller.constraint_frames)]
    level_one = np.vstack([A for A, _ in blocks])
    level_one_rhs = np.concatenate([b for _, b in blocks])
    assert np.max(np.abs(level_one @ qd - level_one_rhs)) <= 1e-9
    # the collision rows at the least-squares value they have in the null space of the
    # equality rows: A_1^+ b_1 + N_1 (A_2 N_1)^+ (b_2 - A_2 A_1^+ b_1), written here
    rows = rows_at(collisions, model, touching)
    second = rows.rows[list(controller.report.active_pairs)]
    second_rhs = rows.lower[list(controller.report.active_pairs)]
    first = pseudo_inverse(level_one) @ level_one_rhs
    _, s, vt = np.linalg.svd(level_one)
    null_basis = vt[int(np.sum(s > 1e-10 * max(1.0, s[0]))):].T
    reference = first + null_basis @ pseudo_inverse(second @ null_basis) @ (second_rhs - second @ first)
    np.testing.assert_allclose(second @ qd, second @ reference, rtol=0, atol=1e-9)
    assert rows.violation(qd)[rows.pairs.index(pair)] > 1e-3  # the pair is not held


def test_without_a_conflict_the_collision_rows_are_held_exactly(dual, apart):
    """No conflict: every active collision row at its bound, as the stacked solve holds it."""
    collisions = CollisionAvoidance(dual)
    q = drive(dual, apart, 12)  # the tools' links inside the detection distance
    controller = CJMController(dual, holes_at(dual, q), backend="python", collisions=collisions,
                               twist_weight=TRANSLATION)
    qd = controller.solve(q, push_together(dual, q, 0.5))
    report = controller.report
    assert report.active_pairs, controller.info
    rows = rows_at(collisions, dual.model, q)
    active = list(report.active_pairs)
    np.testing.assert_allclose(rows.rows[active] @ qd, rows.lower[active], rtol=0, atol=1e-10)


def test_collisions_can_be_set_and_removed(dual, apart):
    controller = CJMController(dual, backend="compiled", twist_weight=TRANSLATION)
    twist = push_together(dual, apart, 0.05)
    without = controller.solve(apart, twist)
    assert controller.info.minimum_distance == np.inf and controller.info.closest_pair == ""
    controller.set_collisions(CollisionAvoidance(dual))
    controller.solve(apart, twist)
    assert controller.info.minimum_distance < controller.collisions.detection_distance
    controller.set_collisions(None)
    np.testing.assert_array_equal(controller.solve(apart, twist), without)


def test_the_command_box_reads_the_grown_steps_commands(dual, apart):
    """An obstacle added after the build gives more pairs than the compiled step's buffer
    holds: the step is built again and its arrays move. The controller's box still counts
    from them: a stop within ``a dt`` of the last command, the next command within
    ``a dt`` of the stop, and a reset that zeroes what the step counts from."""
    collisions = CollisionAvoidance(dual)
    q = drive(dual, apart, 7)
    cjm = CJMController(dual, backend="compiled", collisions=collisions, twist_weight=TRANSLATION,
                        acceleration_limit=dual.acceleration_limit)
    twist = push_together(dual, q, 0.5)
    cjm.solve(q, twist)
    capacity = cjm.step.pair_capacity
    for tip in tips(dual, q):
        collisions.add_obstacle(Sphere(tip.translation - [0.0, 0.0, 0.03], 0.01))
    last = cjm.solve(q, twist)
    assert cjm.step.pair_capacity > capacity  # grown: the case under test
    window = dual.acceleration_limit * cjm.dt * (1.0 + 1e-9)
    stop = cjm.stop(q)
    assert np.all(np.abs(stop - last) <= window) and np.abs(stop - last).max() > 0.0
    np.testing.assert_array_equal(cjm.step.previous, stop)
    assert np.all(np.abs(cjm.solve(q, twist) - stop) <= window)
    cjm.reset()
    np.testing.assert_array_equal(cjm.step.previous, 0.0)
    np.testing.assert_array_equal(cjm.step.previous_change, 0.0)


def test_the_compiled_step_grows_its_buffer_for_more_collision_rows(dual, apart):
    """More rows near than the buffer holds (obstacles added after the build): the C++ step
    is built again with room for them and agrees with the Python step."""
    from controllers.cjm.compiled import CompiledStep

    collisions = CollisionAvoidance(dual)
    q = drive(dual, apart, 7)
    python = CJMController(dual, backend="python", collisions=collisions, twist_weight=TRANSLATION)
    compiled = CJMController(dual, backend="compiled", collisions=collisions, twist_weight=TRANSLATION)
    compiled.step = CompiledStep(compiled.setup, compiled.data, pair_capacity=0)
    twist = push_together(dual, q, 0.5)
    expected, actual = python.solve(q, twist), compiled.solve(q, twist)
    rows = rows_at(collisions, dual.model, q)
    assert rows.size > 0  # rows to hold where the buffer had room for none
    assert python.info.active_pairs and compiled.info.active_pairs == python.info.active_pairs
    np.testing.assert_allclose(actual, expected, rtol=0,
                               atol=collision_rounding_bound(python, q) * (1.0 + np.max(np.abs(expected))))
    assert compiled.step.pair_capacity >= rows.size
