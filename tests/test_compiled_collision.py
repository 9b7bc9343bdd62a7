"""The collision rows measured inside the compiled step (docs/design.md section 18.4)
against coal and the Python rows.

* Primitive pairs (sphere, capsule, box against those and a half-space), drawn with their
  sizes and poses, touching and penetrating included: the extension's signed distance is
  coal's, its witness points lie on their bodies' surfaces at that distance along its
  normal, and where the closest points are unique they are coal's.
* ``sda10f_dual`` with an obstacle of every kind near its arms, at drawn configurations:
  the compiled rows are ``CollisionAvoidance.rows`` (the Python reference, coal's
  distances), pair by pair, and the two CJM steps agree.
* A moved obstacle is seen at the next step, added and removed obstacles rebuild the
  description, and a body the extension does not cover (a mesh's hull) leaves the rows
  to Python, which says so.
"""

from __future__ import annotations

import math

import coal
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from constraints.collision import Box, Capsule, CollisionAvoidance, HalfSpace, Sphere
from constraints.collision.avoidance import GJK_TOLERANCE
from constraints.collision.primitives import PRIMITIVE_KINDS
from controllers import CJMController
from controllers.cjm._step import shape_distance
from teleop.experiments.bench_problems import close_arms
from teleop.robots import load_robot
from test_collision_cjm import TRANSLATION, collision_rounding_bound, push_together

#: coal's distance is exact to rounding for spheres, capsules and half-spaces (closed
#: forms) and stops its GJK / EPA at the tolerance the Python rows ask (GJK_TOLERANCE,
#: 1e-10) with a box: measured over 20,000 random pairs of 0.01-0.5 m, the distances agree
#: to 5e-11 m, separated witness points to 2e-10 m and normals to 2e-9; the bounds below
#: leave a factor 5-20 over that.
DISTANCE_TOLERANCE = 1e-9
WITNESS_TOLERANCE = 1e-8
#: coal's GJK at contact (its relative stopping test is meaningless at distance 0): two
#: boxes touching face to face measured 3e-8 m at 2.4e-7 rad between the faces and 1.9e-7 m
#: at 2e-6 rad; the extension's separating axes give 0 to rounding
COAL_CONTACT_TOLERANCE = 1e-6
#: a witness point's distance to its own body's surface, computed here (rounding on 1 m)
SURFACE_TOLERANCE = 1e-9
SETTINGS = settings(max_examples=500, deadline=None)
ROBOT_SETTINGS = settings(max_examples=25, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow,
                                                 HealthCheck.function_scoped_fixture])

sizes = st.floats(0.01, 0.2)
coordinates = st.floats(-0.3, 0.3)


@st.composite
def poses(draw) -> pin.SE3:
    """A pose: a translation within 0.3 m and a rotation from a drawn quaternion (zeros
    included, so faces and axes aligned with each other too)."""
    quaternion = np.array([draw(st.floats(-1.0, 1.0)) for _ in range(4)])
    assume(np.linalg.norm(quaternion) > 0.1)
    quaternion /= np.linalg.norm(quaternion)
    rotation = pin.Quaternion(*quaternion).matrix()
    return pin.SE3(rotation, np.array([draw(coordinates) for _ in range(3)]))


@st.composite
def shapes(draw, kinds: tuple[str, ...]) -> tuple[str, np.ndarray]:
    """A primitive's kind and dimensions (the extension's: radius, half length, half sides)."""
    kind = draw(st.sampled_from(kinds))
    if kind == "sphere":
        return kind, np.array([draw(sizes), 0.0, 0.0])
    if kind == "capsule":
        # a point or at least 1 mm long: coal mis-measures a capsule of length about
        # 1e-7 m (two crossing capsules, the second 2e-7 m long: -0.125 m for -0.25 m)
        return kind, np.array([draw(sizes), draw(st.just(0.0) | st.floats(1e-3, 0.2)), 0.0])
    if kind == "box":
        return kind, np.array([draw(sizes) for _ in range(3)])
    return kind, np.zeros(3)


BODY_KINDS = ("sphere", "capsule", "box")


def coal_shape(kind: str, dimensions: np.ndarray) -> coal.CollisionGeometry:
    if kind == "sphere":
        return coal.Sphere(dimensions[0])
    if kind == "capsule":
        return coal.Capsule(dimensions[0], 2.0 * dimensions[1])
    if kind == "box":
        return coal.Box(*(2.0 * dimensions))
    return coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.0)


def surface_distance(kind: str, dimensions: np.ndarray, pose: pin.SE3, point: np.ndarray) -> float:
    """The signed distance (m) of a world ``point`` to a posed primitive, written here."""
    local = pose.rotation.T @ (point - pose.translation)
    if kind == "sphere":
        return float(np.linalg.norm(local) - dimensions[0])
    if kind == "capsule":
        axis_point = np.array([0.0, 0.0, np.clip(local[2], -dimensions[1], dimensions[1])])
        return float(np.linalg.norm(local - axis_point) - dimensions[0])
    if kind == "box":
        excess = np.abs(local) - dimensions
        return float(np.linalg.norm(np.maximum(excess, 0.0)) + min(excess.max(), 0.0))
    return float(local[2])


def compiled_distance(first, first_pose, second, second_pose):
    return shape_distance(PRIMITIVE_KINDS.index(first[0]), first[1], first_pose.homogeneous,
                          PRIMITIVE_KINDS.index(second[0]), second[1], second_pose.homogeneous)


def coal_distance(first, first_pose, second, second_pose) -> coal.DistanceResult:
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    request.gjk_tolerance = request.epa_tolerance = GJK_TOLERANCE
    coal.distance(coal_shape(*first), coal.Transform3s(first_pose.rotation, first_pose.translation),
                  coal_shape(*second), coal.Transform3s(second_pose.rotation, second_pose.translation),
                  request, result)
    return result


def coal_parallel_error(first, second, first_pose, second_pose) -> float:
    """coal's error (m) on two capsules whose axes it takes as parallel: up to their length
    times the sine of their angle, the drift of one axis along the other (2.5e-9 m at 2e-8
    rad on 0.125 m crossing, 1.5e-5 m at 2e-3 rad on 7.8 mm side by side). Probed: it does
    when the axes' ``a e - b^2`` of Ericson's closest points, ``(2 h_1 2 h_2 sin)^2``, is
    below about 1e-14; here when ``4 h_1 h_2 sin < 1e-6``
    (1e-12 for that square); zero for any other pair."""
    if (first[0], second[0]) != ("capsule", "capsule"):
        return 0.0
    sine = float(np.linalg.norm(np.cross(first_pose.rotation[:, 2], second_pose.rotation[:, 2])))
    parallel = 4.0 * first[1][1] * second[1][1] * sine < 1e-6
    return 2.0 * max(first[1][1], second[1][1]) * sine if parallel else 0.0


def unique_closest_points(first, second, first_pose, second_pose) -> bool:
    """Whether the closest points of two separated primitives are unique: a sphere's are
    (a point's nearest point on a convex body is), and two capsules' unless their axes
    are parallel; a box's face may lie parallel to the other body."""
    kinds = {first[0], second[0]}
    if "sphere" in kinds:
        return True
    if kinds == {"capsule"}:
        cross = np.cross(first_pose.rotation[:, 2], second_pose.rotation[:, 2])
        return bool(np.linalg.norm(cross) > 1e-3 and first[1][1] > 0.0 and second[1][1] > 0.0)
    return False


# -- primitive pairs against coal ----------------------------------------------------------

@SETTINGS
@given(first=shapes(BODY_KINDS), second=shapes((*BODY_KINDS, "halfspace")),
       first_pose=poses(), second_pose=poses())
def test_primitive_distances_and_witness_points_equal_coal(first, second, first_pose, second_pose):
    distance, on_first, on_second, normal = compiled_distance(first, first_pose, second, second_pose)
    reference = coal_distance(first, first_pose, second, second_pose)
    assert abs(distance - reference.min_distance) <= DISTANCE_TOLERANCE + coal_parallel_error(
        first, second, first_pose, second_pose), \
        (distance, reference.min_distance)
    assert abs(np.linalg.norm(normal) - 1.0) <= 1e-12
    if distance > 0.0:
        # the witness points are on their bodies, ``distance`` apart along the normal
        assert abs(surface_distance(*first, first_pose, on_first)) <= SURFACE_TOLERANCE
        assert abs(surface_distance(*second, second_pose, on_second)) <= SURFACE_TOLERANCE
        np.testing.assert_allclose(on_first - on_second, distance * normal, rtol=0, atol=1e-12)
        # the normal of two separated convex bodies is unique: coal's, negated, except
        # where coal takes two capsules as parallel (its normal then tilts with its
        # error; the witness points' check above holds ours)
        if not coal_parallel_error(first, second, first_pose, second_pose):
            np.testing.assert_allclose(normal, -np.asarray(reference.normal), rtol=0,
                                       atol=WITNESS_TOLERANCE)
        if unique_closest_points(first, second, first_pose, second_pose):
            np.testing.assert_allclose(on_first, reference.getNearestPoint1(), rtol=0,
                                       atol=WITNESS_TOLERANCE)
            np.testing.assert_allclose(on_second, reference.getNearestPoint2(), rtol=0,
                                       atol=WITNESS_TOLERANCE)
    else:
        # penetrating: each witness point is its body's deepest point along the normal,
        # inside (or on) the other body, and the normal separates them by the depth
        assert surface_distance(*first, first_pose, on_first) <= SURFACE_TOLERANCE
        assert surface_distance(*second, second_pose, on_second) <= SURFACE_TOLERANCE
        assert normal @ (on_first - on_second) <= distance + 1e-12 or second[0] == "halfspace"


@pytest.mark.slow
@SETTINGS
@given(first=shapes(BODY_KINDS), second=shapes((*BODY_KINDS, "halfspace")),
       first_pose=poses(), second_pose=poses())
def test_touching_primitives_are_at_distance_zero(first, second, first_pose, second_pose):
    """Two separated primitives, the second moved by their distance along the normal: they
    touch (distance 0 in the extension and in coal, to DISTANCE_TOLERANCE)."""
    distance, _, _, normal = compiled_distance(first, first_pose, second, second_pose)
    assume(distance > 1e-3)
    touching = pin.SE3(second_pose.rotation, second_pose.translation + distance * normal)
    moved, _, _, _ = compiled_distance(first, first_pose, second, touching)
    assert abs(moved) <= DISTANCE_TOLERANCE
    assert abs(coal_distance(first, first_pose, second, touching).min_distance) <= COAL_CONTACT_TOLERANCE


# -- the rows on sda10f_dual against the Python rows -------------------------------------------

@pytest.fixture(scope="module")
def dual():
    return load_robot("sda10f_dual")


@pytest.fixture(scope="module")
def close(dual) -> np.ndarray:
    """The arms close together (the bench's configuration, teleop.experiments.bench)."""
    return close_arms(dual, CollisionAvoidance(dual))


def tool_tips(robot, q: np.ndarray) -> list[np.ndarray]:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return [data.oMf[robot.model.getFrameId(frame)].translation.copy() for frame in robot.ee_frames]


def every_kind_near(robot, q: np.ndarray, rng: np.random.Generator) -> list:
    """A sphere, a box, a capsule and a half-space a few centimetres from the tools, moving."""
    left, right = tool_tips(robot, q)
    between = 0.5 * (left + right)
    tilt = rng.uniform(-0.3, 0.3, 2)
    normal = np.array([tilt[0], tilt[1], 1.0]) / np.linalg.norm([tilt[0], tilt[1], 1.0])
    return [Sphere(left + rng.uniform(-0.08, 0.08, 3), 0.03, velocity=rng.normal(scale=0.1, size=3)),
            Box(right + rng.uniform(-0.1, 0.1, 3), rng.uniform(0.02, 0.1, 3),
                rpy=rng.uniform(-np.pi, np.pi, 3), velocity=rng.normal(scale=0.1, size=3)),
            Capsule(between + rng.uniform(-0.1, 0.1, 3), 0.02, 0.15, axis=unit(rng.normal(size=3))),
            HalfSpace(min(left[2], right[2]) * np.array([0.0, 0.0, 1.0]) - rng.uniform(0.0, 0.1) * normal
                      + np.array([left[0], left[1], 0.0]), normal,
                      velocity=rng.normal(scale=0.05, size=3))]


def unit(vector: np.ndarray) -> np.ndarray:
    return vector / np.linalg.norm(vector)


def body_poses(collisions: CollisionAvoidance, model, q: np.ndarray):
    """Each body's and obstacle's kind, dimensions and world pose (Pinocchio's placements)."""
    description = collisions.primitives()
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    shapes_and_poses = [(PRIMITIVE_KINDS[kind], dimensions, data.oMi[int(joint)] * pin.SE3(placement))
                        for kind, dimensions, joint, placement in
                        zip(description.body_kinds, description.body_dimensions,
                            description.body_joints, description.body_placements)]
    shapes_and_poses += [(PRIMITIVE_KINDS[kind], dimensions, pin.SE3(rotation, obstacle.center))
                         for kind, dimensions, rotation, obstacle in
                         zip(description.obstacle_kinds, description.obstacle_dimensions,
                             description.obstacle_rotations, description.obstacles)]
    return description, shapes_and_poses


def point_row(model, data, joint: int, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """``n^T J_p`` of the world ``point`` carried by ``joint`` (Pinocchio's world-aligned
    Jacobian at the joint, shifted to the point)."""
    jacobian = pin.getJointJacobian(model, data, joint, pin.LOCAL_WORLD_ALIGNED)
    arm = point - data.oMi[joint].translation
    return normal @ jacobian[:3] + np.cross(arm, normal) @ jacobian[3:]


@ROBOT_SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_the_compiled_rows_are_the_python_rows(dual, close, seed):
    """Same pairs within d_i, same distances, normals and bounds; the same rows where the
    witness points are unique, else both witness pairs closest points of their bodies
    (on the surfaces, the distance apart) and the compiled row the distance rate at its
    own witness points."""
    model = dual.model
    rng = np.random.default_rng(seed)
    q = pin.integrate(model, close, rng.uniform(-0.05, 0.05, model.nv))
    collisions = CollisionAvoidance(dual, every_kind_near(dual, q, rng))
    controller = CJMController(dual, backend="compiled", collisions=collisions, twist_weight=TRANSLATION)
    controller.solve(q, np.zeros(12))
    assert controller.step.collision_rows.fallback is None
    compiled = controller.report.collision
    assert collisions.last_rows is compiled
    indices = controller.step.collision_rows.pair_indices()
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    expected = collisions.rows(model, data)
    assert compiled.pairs == expected.pairs
    assert (compiled.closest_pair, compiled.size) == (expected.closest_pair, expected.size)
    assert math.isclose(compiled.minimum_distance, expected.minimum_distance, rel_tol=0.0,
                        abs_tol=DISTANCE_TOLERANCE)
    description, placed = body_poses(collisions, model, q)
    velocities = [np.zeros(3)] * len(description.body_kinds) + [o.velocity for o in description.obstacles]
    for i, index in enumerate(indices.tolist()):
        first, second = description.pairs[index].tolist()
        distance = compiled.distances[i]
        assert abs(distance - expected.distances[i]) <= DISTANCE_TOLERANCE
        on_first, on_second = compiled.witnesses[i]
        if distance <= 0.0:
            continue  # penetrating: the witness points follow another convention (docs 18.4)
        normal = (on_first - on_second) / distance
        reference_normal = (expected.witnesses[i][0] - expected.witnesses[i][1]) / expected.distances[i]
        np.testing.assert_allclose(normal, reference_normal, rtol=0, atol=WITNESS_TOLERANCE)
        gain = collisions.gain
        np.testing.assert_allclose(compiled.lower[i], expected.lower[i], rtol=0,
                                   atol=gain * DISTANCE_TOLERANCE
                                   + np.linalg.norm(velocities[second]) * WITNESS_TOLERANCE)
        row = point_row(model, data, int(description.body_joints[first]), on_first, normal)
        if second < len(description.body_kinds):
            row -= point_row(model, data, int(description.body_joints[second]), on_second, normal)
        # the normal taken from the witness points here: rounding of the points over the
        # distance (the extension's normal is its cores')
        np.testing.assert_allclose(compiled.rows[i], row, rtol=0,
                                   atol=1e-12 + 10 * np.finfo(float).eps / distance, err_msg=str(distance))
        if np.abs(compiled.witnesses[i] - expected.witnesses[i]).max() <= WITNESS_TOLERANCE:
            np.testing.assert_allclose(compiled.rows[i], expected.rows[i], rtol=0,
                                       atol=10 * WITNESS_TOLERANCE)
        else:  # closest points not unique (a box's face parallel to the other body)
            for point, body in ((on_first, first), (on_second, second),
                                (expected.witnesses[i][0], first), (expected.witnesses[i][1], second)):
                assert abs(surface_distance(*placed[body][:2], placed[body][2], point)) <= 1e-8


#: the rows of the two backends agree to WITNESS_TOLERANCE where their witness points do:
#: the commands then agree to that times the conditioning collision_rounding_bound counts
#: (it bounds a perturbation of eps relative; this one is WITNESS_TOLERANCE)
ROW_AGREEMENT = WITNESS_TOLERANCE / np.finfo(float).eps


@ROBOT_SETTINGS
@given(seed=st.integers(0, 2**32 - 1), speed=st.sampled_from([0.01, 0.1, 0.5]))
def test_the_compiled_and_python_steps_agree_with_every_obstacle_kind(dual, close, seed, speed):
    """The two CJM steps, the tools pushed together among a sphere, a box, a capsule and
    a half-space, where no pair penetrates and every pair's closest points are unique
    (the two measure the same rows there, to WITNESS_TOLERANCE)."""
    model = dual.model
    rng = np.random.default_rng(seed)
    q = pin.integrate(model, close, rng.uniform(-0.05, 0.05, model.nv))
    apart = [obstacle for obstacle in every_kind_near(dual, q, rng)
             if CollisionAvoidance(dual, [obstacle], self_collision=False).minimum_distance(q)[0] > 0.0]
    collisions = CollisionAvoidance(dual, apart)
    python, compiled = (CJMController(dual, backend=backend, collisions=collisions,
                                      twist_weight=TRANSLATION) for backend in ("python", "compiled"))
    twist = push_together(dual, q, speed)
    expected = python.solve(q, twist)
    reference = python.report.collision
    actual = compiled.solve(q, twist)
    rows = compiled.report.collision
    assume(rows.size == 0 or rows.distances.min() > 0.0)
    assume(np.abs(rows.witnesses - reference.witnesses).max(initial=0.0) <= WITNESS_TOLERANCE)
    bound = collision_rounding_bound(python, q) * ROW_AGREEMENT * (1.0 + float(np.max(np.abs(expected))))
    assert float(np.max(np.abs(actual - expected))) <= bound, (python.info, compiled.info)
    a, b = python.info, compiled.info
    assert (b.status, b.active_pairs, b.closest_pair) == (a.status, a.active_pairs, a.closest_pair)
    assert math.isclose(b.minimum_distance, a.minimum_distance, rel_tol=0.0, abs_tol=DISTANCE_TOLERANCE)


# -- obstacles moved, added and removed ----------------------------------------------------------

def test_a_moved_obstacle_is_seen_at_the_next_step(dual, close):
    """``move_to`` replaces the centre and velocity arrays; the next compiled step reads
    them (its rows those Python measures at the new place), an unchanged one is kept."""
    model = dual.model
    left, _ = tool_tips(dual, close)
    ball = Sphere(left + [0.0, 0.0, 0.6], 0.03)
    collisions = CollisionAvoidance(dual, [ball], self_collision=False)
    controller = CJMController(dual, backend="compiled", collisions=collisions, twist_weight=TRANSLATION)
    controller.solve(close, np.zeros(12))
    assert controller.report.collision.size == 0
    ball.move_to(left + [0.0, 0.0, 0.06], velocity=(0.0, 0.0, -0.2))
    controller.solve(close, np.zeros(12))
    compiled = controller.report.collision
    data = model.createData()
    pin.computeJointJacobians(model, data, close)
    expected = collisions.rows(model, data)
    assert compiled.size == expected.size > 0
    np.testing.assert_allclose(compiled.distances, expected.distances, rtol=0, atol=DISTANCE_TOLERANCE)
    np.testing.assert_allclose(compiled.lower, expected.lower, rtol=0, atol=1e-8)
    controller.solve(close, np.zeros(12))  # not moved: the same rows
    np.testing.assert_array_equal(controller.report.collision.lower, compiled.lower)
    ball.move_to(ball.position)  # stopped: the feed-forward gone from the bounds
    controller.solve(close, np.zeros(12))
    normals = (compiled.witnesses[:, 0] - compiled.witnesses[:, 1]) / compiled.distances[:, None]
    np.testing.assert_allclose(controller.report.collision.lower,
                               compiled.lower - normals @ np.array([0.0, 0.0, -0.2]), rtol=0, atol=1e-12)


def test_added_and_removed_obstacles_rebuild_the_description(dual, close):
    left, _ = tool_tips(dual, close)
    collisions = CollisionAvoidance(dual, self_collision=False)
    controller = CJMController(dual, backend="compiled", collisions=collisions, twist_weight=TRANSLATION)
    controller.solve(close, np.zeros(12))
    assert controller.report.collision.size == 0
    ball = Sphere(left + [0.0, 0.0, 0.06], 0.03, name="ball")
    collisions.add_obstacle(ball)
    controller.solve(close, np.zeros(12))
    assert controller.report.collision.size > 0
    assert all(pair.endswith("| ball") for pair in controller.report.collision.pairs)
    assert controller.step.pair_capacity >= len(collisions.pairs)
    collisions.remove_obstacle(ball)
    controller.solve(close, np.zeros(12))
    assert controller.report.collision.size == 0


# -- a body the extension does not cover ----------------------------------------------------------

class MeshRobot:
    """sda10f with its torso box as a mesh (its convex hull: not a primitive)."""

    def __init__(self, robot) -> None:
        self.model, self.q_home = robot.model, robot.q_home
        self.ee_frames, self.name = robot.ee_frames, robot.name
        self.collision_model = robot.collision_model.copy()
        for item in self.collision_model.geometryObjects:
            if isinstance(item.geometry, coal.Box):
                half = np.asarray(item.geometry.halfSide)
                corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
                mesh = coal.BVHModelOBBRSS()
                mesh.beginModel(12, 8)
                mesh.addVertices(corners)
                mesh.addTriangles(np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5],
                                            [0, 5, 1], [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4],
                                            [1, 5, 7], [1, 7, 3]]))
                mesh.endModel()
                item.geometry = mesh
                return
        raise AssertionError("no box to replace")


def test_a_mesh_body_leaves_the_rows_to_python_and_says_so(sda10f):
    robot = MeshRobot(sda10f)
    collisions = CollisionAvoidance(robot, [HalfSpace([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])],
                                    self_collision=False)
    assert collisions.primitives().uncovered == ("torso_link_0",)
    controller = CJMController(sda10f, backend="compiled", collisions=collisions)
    q = sda10f.q_home
    twist = np.array([0.05, 0.0, -0.05, 0.0, 0.0, 0.0])
    python = CJMController(sda10f, backend="python", collisions=collisions)
    expected = python.solve(q, twist)
    actual = controller.solve(q, twist)
    fallback = controller.step.collision_rows.fallback
    assert fallback is not None and "torso_link_0" in fallback
    assert controller.report.collision.pairs == python.report.collision.pairs
    np.testing.assert_allclose(controller.report.collision.rows, python.report.collision.rows, rtol=0, atol=0)
    np.testing.assert_allclose(actual, expected, rtol=0, atol=1e-9)
