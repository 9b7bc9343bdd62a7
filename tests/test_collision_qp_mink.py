"""Collision rows in the QP baseline and in the mink peer (docs/design.md 18.5).

* A pair at exactly ``d_s`` with the twist pushing them together: the QP's command keeps
  ``rows qd >= lower`` (proxqp, daqp, osqp, each to its tolerance), and the distance's
  rate measured here by central differences of coal's distance at ``q -/+ h qd`` is not
  below the damper's bound; the step names the pair.
* With one collision row active and nothing else binding, the QP's command is the
  null-space solution written here: ``qd = [J_e; c]^+ [V; l]``.
* A pair that a ``PointLock`` keeps from moving out: the least-residual stage leaves the
  row and the lock equal misses, the step is ``constraint_degraded`` naming the pair (the
  QP; mink, whose own bound inside ``d_s`` is 0, once the lock pulls the link in).
* mink's MuJoCo geoms are the avoidance's shapes (primitives and convex hulls):
  ``mj_geomDistance`` over each pair's geoms equals the avoidance's coal distance, and
  they follow the obstacles as they move, come and go.
* Both trocars held to 1 um while the arms of ``sda10f_dual`` are pushed into each other
  (``q = pin.integrate(model, q, qd dt)``): the true minimum distance stays above
  ``d_s - 0.5 mm`` for the QP and mink on three backends, the step names the pair.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings

import coal
import mujoco
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from example_robots import EXAMPLE_ARMS
from hypothesis import strategies as st
from strategies import unit3

from constraints import Hole, PointLock
from constraints.collision import Box, CollisionAvoidance, HalfSpace, Sphere
from controllers import MinkController, QPController, StepStatus
from teleop import load_robot

#: how far each QP backend's command may break a collision row (m/s): ten times its
#: absolute tolerance (controllers.numerics.SOLVER_SETTINGS: proxqp 1e-10, daqp's
#: primal_tol 1e-10, OSQP 1e-7); the rows' entries are of order one (m per rad).
ROW_TOLERANCE = {"proxqp": 1e-9, "daqp": 1e-9, "osqp": 1e-6}
#: the least-residual split (m/s), against what was measured over 64 drawn cases: proxqp
#: 8e-8 (its tolerance, 1e-11 at most, over the stage's small curvature), daqp 3e-17,
#: OSQP 3e-11 (polished); OSQP gets ten times its eps_abs all the same
SPLIT_TOLERANCE = {"proxqp": 1e-6, "daqp": 1e-9, "osqp": 1e-6}
#: central-difference step (s) and the error allowed on a distance's rate (m/s): the
#: truncation (h^2 d_ddd / 6) and the rounding (eps d / h) are orders below it
STEP, RATE_ERROR = 1e-4, 1e-6
#: agreement of the QP with the null-space solution (rad/s), as tests/test_qp_priorities.py
AGREEMENT = 1e-6
#: MuJoCo's distances against coal's (m): coal's GJK stops at its default tolerance 1e-6
#: (a box against a capsule measured 1.1e-6 off at 10 cm; the primitives' analytic pairs
#: agree to 1e-15)
SHAPE_AGREEMENT = 1e-5
#: the closest the pushed arms may come: d_s minus 0.5 mm (issue 21)
MARGIN = 0.5e-3
#: the trocars' position error allowed while the arms are pushed (m)
TROCAR = 1e-6

PROPERTY = settings(max_examples=25, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
BARE = dict(position_limits=False, velocity_limits=False, singular_threshold=0.0,
            posture_gain=0.0)
# every controller here runs on its iteration caps alone (time_budget=None): a loaded
# machine's CPU time must not decide a step


@functools.cache
def sda10f():
    return load_robot("sda10f")


@functools.cache
def dual():
    return load_robot("sda10f_dual")


@functools.cache
def ur5():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # meshes it cannot draw: not needed here
        return EXAMPLE_ARMS["ur5"].load()


def kinematics(robot, q: np.ndarray) -> pin.Data:
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    return data


def sphere_beside(robot, q: np.ndarray, frame: str, direction: np.ndarray, gap: float,
                  radius: float = 0.05) -> Sphere:
    """A sphere ``gap`` m from the robot, towards ``direction`` from ``frame``: placed,
    then moved along the normal of its nearest pair until that pair is ``gap`` apart."""
    data = kinematics(robot, q)
    origin = data.oMf[robot.model.getFrameId(frame)].translation
    sphere = Sphere(origin + (0.1 + radius) * direction, radius)
    probe = CollisionAvoidance(robot, [sphere], self_collision=False, detection_distance=1.0)
    rows = probe.rows(robot.model, data)
    nearest = int(np.argmin(rows.distances))
    on_robot = rows.witnesses[nearest, 0]
    normal = (sphere.center - on_robot) / np.linalg.norm(sphere.center - on_robot)
    sphere.move_to(sphere.center + (gap - rows.distances[nearest]) * normal)
    return sphere


def push_towards(robot, q: np.ndarray, point: np.ndarray, speed: float) -> np.ndarray:
    """The tool's body twist translating it towards the world ``point`` at ``speed``."""
    tool = kinematics(robot, q).oMf[robot.model.getFrameId(robot.ee_frame)]
    direction = (point - tool.translation) / np.linalg.norm(point - tool.translation)
    return np.concatenate([tool.rotation.T @ (speed * direction), np.zeros(3)])


def distance_rate(collisions: CollisionAvoidance, robot, q: np.ndarray, qd: np.ndarray,
                  pair: str) -> float:
    """``d_dot`` of ``pair`` (its nearest geometries) along ``qd``: central differences of
    coal's distance."""
    def distance(sign: float) -> float:
        data = robot.model.createData()
        pin.forwardKinematics(robot.model, data, pin.integrate(robot.model, q, sign * STEP * qd))
        return min(d for name, d in collisions.distances(robot.model, data) if name == pair)
    return (distance(1.0) - distance(-1.0)) / (2.0 * STEP)


configurations = st.lists(st.floats(-0.3, 0.3), min_size=8, max_size=8).map(np.array)


@pytest.mark.parametrize("solver", ["proxqp", "daqp", "osqp"])
@PROPERTY
@given(offset=configurations, direction=unit3, speed=st.floats(0.05, 0.5))
@example(offset=np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -0.25, 0.0]),  # two nearly equal rows
         direction=np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0), speed=0.5)
def test_pair_at_safety_distance_does_not_close(solver, offset, direction, speed):
    robot = sda10f()
    q = robot.q_home + offset
    sphere = sphere_beside(robot, q, robot.ee_frame, direction, gap=0.005)
    collisions = CollisionAvoidance(robot, [sphere], self_collision=False)
    rows = collisions.rows(robot.model, kinematics(robot, q))
    assume(rows.size and abs(rows.minimum_distance - collisions.safety_distance) < 1e-9)
    twist = push_towards(robot, q, sphere.center, speed)
    free = QPController(robot, solver=solver, time_budget=None).solve(q, twist)
    assume(np.max(rows.violation(free)) > 1e-4)  # without the rows the pair would close

    controller = QPController(robot, solver=solver, collisions=collisions, time_budget=None)
    qd = controller.solve(q, twist)

    assert np.max(rows.violation(qd)) <= ROW_TOLERANCE[solver]
    held = [i for i in range(rows.size) if rows.distances[i] < collisions.safety_distance + 1e-9]
    for index in held:  # lower = 0 at d_s: the measured distance does not decrease
        rate = distance_rate(collisions, robot, q, qd, rows.pairs[index])
        assert rate >= rows.lower[index] - ROW_TOLERANCE[solver] - RATE_ERROR
    info = controller.info
    assert info.minimum_distance == pytest.approx(collisions.safety_distance, abs=1e-9)
    assert info.closest_pair == rows.closest_pair
    if info.status is StepStatus.FAILED:  # an honest stop (zero command): proxqp only
        assert solver == "proxqp" and "iteration limit" in info.message, info.message
        return
    if info.status is not StepStatus.OK:  # the push is held back: the step says by what
        assert info.status is StepStatus.LEAST_SQUARES
        assert info.active_pairs and all(name in info.message for name in info.active_pairs)
        assert "held back by collision pair" in info.message


@pytest.mark.parametrize("solver", ["proxqp", "daqp"])
@PROPERTY
@given(offset=configurations, direction=unit3, gap=st.floats(0.002, 0.004),
       twist_direction=unit3, speed=st.floats(0.0, 0.2))
def test_one_active_row_is_the_null_space_solution(solver, offset, direction, gap,
                                                   twist_direction, speed):
    """With no limit, no damping and no posture, the lexicographic QP's command under one
    active collision row ``c qd >= l`` is the minimum-norm ``qd`` with ``J_e qd = V`` and
    ``c qd = l``: ``[J_e; c]^+ [V; l]``. The pair is the elbow's, inside ``d_s``
    (``l > 0``: it must move out, which the minimum-norm ``J_e^+ V`` does not), the twist
    reachable (7 rows, 8 joints)."""
    robot = sda10f()
    q = robot.q_home + offset
    sphere = sphere_beside(robot, q, "arm_link_4_u", direction, gap=gap)
    # rows for the nearest geometries alone (d_i just above the gap)
    collisions = CollisionAvoidance(robot, [sphere], self_collision=False,
                                    detection_distance=0.006, approach_speed=0.05)
    data = kinematics(robot, q)
    rows = collisions.rows(robot.model, data)
    assume(rows.size == 1)
    jacobian = pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(robot.ee_frame),
                                    pin.LOCAL)
    twist = np.concatenate([speed * twist_direction, np.zeros(3)])
    stacked = np.vstack([jacobian, rows.rows])
    assume(np.linalg.svd(stacked, compute_uv=False)[-1] > 1e-2)  # [J_e; c] full row rank
    assume(rows.violation(np.linalg.pinv(jacobian) @ twist)[0] > 1e-3)  # the row binds
    reference = np.linalg.pinv(stacked) @ np.concatenate([twist, rows.lower])

    controller = QPController(robot, solver=solver, collisions=collisions, time_budget=None,
                              **BARE)
    qd = controller.solve(q, twist)

    assert np.max(np.abs(qd - reference)) <= AGREEMENT
    assert controller.info.status is StepStatus.OK  # the twist is met, the row held
    assert controller.info.active_pairs == rows.pairs


#: radius (m) of the elbow's joint housing (the sphere of the URDF's visual)
ELBOW_RADIUS = 0.05175


@functools.cache
def sda10f_with_elbow_housing():
    """``sda10f`` with a collision sphere centred on the elbow link's origin (the built-in
    robot's capsules cover its housing, but no geometry of theirs is centred there)."""
    robot = sda10f()
    geometry = robot.collision_model.copy()
    frame = robot.model.getFrameId("arm_link_4_u")
    geometry.addGeometryObject(pin.GeometryObject(
        "arm_link_4_u_housing", robot.model.frames[frame].parentJoint, frame,
        robot.model.frames[frame].placement, coal.Sphere(ELBOW_RADIUS)))
    return dataclasses.replace(robot, collision_model=geometry)


def locked_elbow_against_a_sphere(offset: np.ndarray, direction: np.ndarray, gap: float):
    """The elbow link's origin locked (``PointLock``) and a sphere ``gap`` (< d_s) from the
    link's housing sphere, which is centred on that origin: the pair's rate is
    ``n . v_origin``, which the lock holds at 0 while the damper asks ``k (d_s - gap) > 0``."""
    robot = sda10f_with_elbow_housing()
    q = robot.q_home + offset
    origin = kinematics(robot, q).oMf[robot.model.getFrameId("arm_link_4_u")].translation
    radius = ELBOW_RADIUS
    sphere = Sphere(origin + (radius + gap + 0.05) * direction, 0.05)
    collisions = CollisionAvoidance(robot, [sphere], self_collision=False)
    lock = PointLock("arm_link_4_u", [0.0, 0.0, 0.0], origin)
    rows = collisions.rows(robot.model, kinematics(robot, q))
    target = [i for i in range(rows.size)
              if rows.pairs[i] == "arm_link_4_u | sphere" and abs(rows.distances[i] - gap) < 1e-9]
    return robot, q, lock, collisions, rows, target


@pytest.mark.parametrize("solver", ["proxqp", "daqp", "osqp"])
@PROPERTY
@given(offset=configurations, direction=unit3, gap=st.floats(0.001, 0.004))
def test_pair_in_conflict_with_a_lock_is_degraded(solver, offset, direction, gap):
    """The lock and the pair conflict: the least-residual stage splits the miss evenly
    (``min |A qd - b|^2 + t^2`` with ``n . v_origin`` shared: each ``l / 2``), the step is
    ``constraint_degraded`` and names the pair."""
    robot, q, lock, collisions, rows, target = locked_elbow_against_a_sphere(offset, direction,
                                                                             gap)
    assume(len(target) == 1)
    others = [i for i in range(rows.size) if i != target[0]]
    assume(np.all(rows.lower[others] < 0.0))  # only the locked pair asks to move out
    controller = QPController(robot, [lock], solver=solver, collisions=collisions,
                              time_budget=None)
    qd = controller.solve(q, np.zeros(6))
    violation = rows.violation(qd)
    assume(np.all(violation[others] < -1e-6))  # no other pair takes part
    A, b = lock.rows(robot.model, kinematics(robot, q), robot.model.getFrameId(lock.link))
    half = rows.lower[target[0]] / 2.0
    tolerance = SPLIT_TOLERANCE[solver]
    assert violation[target[0]] == pytest.approx(half, abs=tolerance)
    assert np.linalg.norm(A @ qd - b) == pytest.approx(half, abs=tolerance)
    info = controller.info
    assert info.status is StepStatus.CONSTRAINT_DEGRADED
    assert ("collision pair arm_link_4_u | sphere "
            f"(d = {1e3 * gap:.2f} mm) cannot be kept apart") in info.message


@settings(max_examples=10, deadline=None)
@given(offset=configurations, direction=unit3, gap=st.floats(0.001, 0.004))
def test_mink_holds_a_pair_inside_the_safety_distance_still(offset, direction, gap):
    """mink, the outside peer, bounds a pair at or inside ``d_s`` by ``d_dot >= 0`` (its
    bound there is 0, where the damper asks ``k (d_s - d) > 0``): with the lock the pair
    stays where it is, the lock held, and the step is ``ok`` by mink's own rows."""
    robot, q, lock, collisions, rows, target = locked_elbow_against_a_sphere(offset, direction,
                                                                             gap)
    assume(len(target) == 1)
    controller = MinkController(robot, [lock], collisions=collisions, time_budget=None)
    qd = controller.solve(q, np.zeros(6))
    rate = rows.rows[target[0]] @ qd
    assert rate >= -1e-9
    assert rate <= rows.lower[target[0]] / 2.0  # not pushed out as the QP's half way
    assert controller.info.equality_residual <= 1e-9
    assert "arm_link_4_u | sphere" in controller.info.active_pairs


@pytest.mark.parametrize("solver", ["proxqp", "daqp", "osqp"])
@settings(max_examples=10, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(offset=configurations, direction=unit3, gap=st.floats(0.001, 0.004))
def test_mink_pair_in_conflict_with_a_pulling_lock_is_degraded(solver, offset, direction, gap):
    """The lock's target 1 mm towards the sphere: its row pulls the link in, which mink's
    own bound (``d_dot >= 0`` inside ``d_s``) refuses. mink's step falls back on the
    least-residual stage (the avoidance's rows), which leaves the pair's row and the lock
    the same miss (``min r_1^2 + r_2^2`` with ``r_1 + r_2`` fixed; to mink's
    ``equality_tolerance``, to which it holds the held rows), and names the pair."""
    robot, q, lock, collisions, rows, target = locked_elbow_against_a_sphere(offset, direction,
                                                                             gap)
    assume(len(target) == 1)
    others = [i for i in range(rows.size) if i != target[0]]
    assume(np.all(rows.lower[others] < 0.0))
    pulling = PointLock(lock.link, lock.link_point, lock.target + 1e-3 * direction)
    controller = MinkController(robot, [pulling], solver=solver, collisions=collisions,
                                time_budget=None)
    qd = controller.solve(q, np.zeros(6))
    info = controller.info
    if info.status is StepStatus.FAILED:
        # ProxQP at its iteration cap, which it does not reach the same way from one call
        # to the next (its result near the cap depends on the process's history): the
        # honest failure, the stop inside the box, said so
        lower, upper = controller.joint_bounds.box(q)
        np.testing.assert_array_equal(qd, np.clip(0.0, lower, upper))
        assert solver == "proxqp" and "iteration limit" in info.message, info.message
        return
    violation = rows.violation(qd)
    assume(np.all(violation[others] < -1e-6))
    A, b = pulling.rows(robot.model, kinematics(robot, q), robot.model.getFrameId(lock.link))
    assert violation[target[0]] > 0.0
    assert violation[target[0]] == pytest.approx(np.linalg.norm(A @ qd - b),
                                                 abs=controller.equality_tolerance)
    assert info.status is StepStatus.CONSTRAINT_DEGRADED
    assert "collision pair arm_link_4_u | sphere" in info.message
    assert "cannot be kept apart" in info.message


def mujoco_and_coal_distances(controller: MinkController, collisions: CollisionAvoidance,
                              robot, q: np.ndarray) -> tuple[dict[str, float], dict[str, float]]:
    """Each pair's distance (its nearest geometries) from mink's MuJoCo model at the last
    step and from the avoidance's coal shapes at ``q``."""
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    coal_distances: dict[str, float] = {}
    for name, distance in collisions.distances(robot.model, data):
        coal_distances[name] = min(distance, coal_distances.get(name, np.inf))
    limit = controller.collision_limit
    mj_distances: dict[str, float] = {}
    fromto = np.zeros(6)
    for (first, second), name in zip(limit.geom_id_pairs, limit.names):
        distance = mujoco.mj_geomDistance(controller.mj_model, controller.configuration.data,
                                          first, second, 10.0, fromto)
        mj_distances[name] = min(distance, mj_distances.get(name, np.inf))
    return mj_distances, coal_distances


def assert_same_distances(mj_distances: dict[str, float], coal_distances: dict[str, float]):
    assert set(mj_distances) == set(coal_distances)
    for name, distance in coal_distances.items():
        if distance > 0.0:
            assert mj_distances[name] == pytest.approx(distance, abs=SHAPE_AGREEMENT), name
        else:  # penetration depths are each library's own: only the sign is shared
            assert mj_distances[name] <= SHAPE_AGREEMENT, name


@settings(max_examples=10, deadline=None)
@given(offset=st.lists(st.floats(-0.4, 0.4), min_size=15, max_size=15).map(np.array))
def test_mink_geoms_are_the_avoidance_shapes(offset):
    """Every pair's distance from mink's MuJoCo geoms (``mj_geomDistance``) is the
    avoidance's coal distance, obstacles (a box, a half-space) included, also after the
    obstacles move (a penetrating pair: both negative)."""
    robot = dual()
    box = Box([0.6, 0.0, -0.1], [0.3, 0.2, 0.1], rpy=[0.1, 0.2, 0.3])
    floor = HalfSpace([0.0, 0.0, -0.5], np.array([0.1, 0.0, 1.0]) / np.hypot(0.1, 1.0))
    collisions = CollisionAvoidance(robot, [box, floor])
    controller = MinkController(robot, collisions=collisions)
    q = robot.q_home + offset
    for move in ([0.0, 0.0, 0.0], [0.05, -0.1, 0.02]):
        box.move_to(box.position + move)
        controller.solve(q, np.zeros(12))
        assert_same_distances(*mujoco_and_coal_distances(controller, collisions, robot, q))


@settings(max_examples=5, deadline=None)
@given(offset=st.lists(st.floats(-0.5, 0.5), min_size=6, max_size=6).map(np.array))
def test_mink_mesh_geoms_are_the_convex_hulls(offset):
    """A robot with mesh collision geometry (the UR5 of example-robot-data): the
    avoidance's convex hulls as MuJoCo meshes give the same distances."""
    robot = ur5()
    collisions = CollisionAvoidance(robot, [Sphere([0.4, 0.2, 0.3], 0.05)])
    controller = MinkController(robot, collisions=collisions)
    q = robot.q_home + offset
    controller.solve(q, np.zeros(6))
    assert_same_distances(*mujoco_and_coal_distances(controller, collisions, robot, q))


# -- both trocars held while the arms are pushed into each other ---------------------------

@functools.cache
def arms_close() -> np.ndarray:
    """A configuration of ``sda10f_dual`` with its two wrists about 7.5 mm apart: the
    tips driven towards each other (no trocar) by the QP with collision avoidance."""
    robot = dual()
    collisions = CollisionAvoidance(robot)
    controller = QPController(robot, solver="daqp", dt=5e-3, collisions=collisions,
                              twist_weight=(1, 1, 1, 0, 0, 0), time_budget=None)
    q = robot.q_home.copy()
    for _ in range(1000):
        q = pin.integrate(robot.model, q, 5e-3 * controller.solve(q, tips_together(q, 0.1)))
        if controller.info.minimum_distance < 0.0075 and "right" in controller.info.closest_pair \
                and "left" in controller.info.closest_pair:
            return q
    raise AssertionError("the tips never came within 7.5 mm")


def tips_together(q: np.ndarray, speed: float) -> np.ndarray:
    """Both tips translating towards each other along the world y axis at ``speed``."""
    robot = dual()
    data = kinematics(robot, q)
    twist = []
    for frame, sign in zip(robot.ee_frames, (-1.0, 1.0)):
        rotation = data.oMf[robot.model.getFrameId(frame)].rotation
        twist.extend([*(rotation.T @ [0.0, sign * speed, 0.0]), 0.0, 0.0, 0.0])
    return np.array(twist)


def push_arms(controller_type, solver: str, steps: int = 300, dt: float = 1e-3):
    """Run the push; returns the smallest true distance, the largest trocar error and the
    last step's info."""
    robot = dual()
    q = arms_close()
    holes = [Hole.on_link(robot, q, 0.08, link=link)
             for link in ("arm_left_link_5_r", "arm_right_link_5_r")]
    collisions = CollisionAvoidance(robot)
    controller = controller_type(robot, holes, solver=solver, dt=dt, collisions=collisions,
                                 time_budget=None)
    closest, trocar = np.inf, 0.0
    for _ in range(steps):
        q = pin.integrate(robot.model, q, dt * controller.solve(q, tips_together(q, 0.05)))
        closest = min(closest, collisions.minimum_distance(q)[0])
        data = kinematics(robot, q)
        trocar = max(trocar, *(float(np.linalg.norm(hole.error(data.oMf[robot.model.getFrameId(
            hole.link)]))) for hole in holes))
    return closest, trocar, controller.info, collisions


@pytest.mark.parametrize("controller_type,solver", [
    (QPController, "proxqp"), (QPController, "daqp"), (QPController, "osqp"),
    (MinkController, "proxqp"), (MinkController, "daqp"), (MinkController, "osqp")])
def test_trocars_held_while_the_arms_are_pushed_together(controller_type, solver):
    """mink, the outside peer, holds the same bound: its limit with ``gain = k dt^2`` is
    the damper above ``d_s`` (docs/design.md 18.5)."""
    closest, trocar, info, collisions = push_arms(controller_type, solver)
    assert closest >= collisions.safety_distance - MARGIN
    assert trocar <= TROCAR
    assert info.status is StepStatus.LEAST_SQUARES
    assert info.active_pairs == ("arm_left_link_7_t | arm_right_link_7_t",)
    assert "held back by collision pair arm_left_link_7_t | arm_right_link_7_t" in info.message
    assert info.closest_pair == "arm_left_link_7_t | arm_right_link_7_t"


def test_mink_follows_the_obstacles_set():
    """Obstacles added after the controller was built get their geoms and pairs at the
    next step (the MuJoCo model rebuilt), one geom pair per avoidance pair; removing them
    takes them away; without collision avoidance there is no collision limit."""
    robot = dual()
    collisions = CollisionAvoidance(robot, self_collision=False)
    controller = MinkController(robot, collisions=collisions)
    assert controller.collision_limit.geom_id_pairs == []
    ball = Sphere([0.65, 0.0, 0.06], 0.1)  # between the two tools
    collisions.add_obstacle(ball)
    controller.solve(robot.q_home, np.zeros(12))
    limit = controller.collision_limit
    assert list(limit.names) == [f"{first} | {second}" for first, second in collisions.pairs]
    assert len(set(limit.geom_id_pairs)) == len(collisions.pairs)
    assert controller.info.closest_pair.endswith("| sphere")
    assert controller.info.minimum_distance < collisions.detection_distance
    collisions.remove_obstacle(ball)
    controller.solve(robot.q_home, np.zeros(12))
    assert controller.collision_limit.geom_id_pairs == []
    controller.set_collisions(None)
    assert controller.collision_limit is None
