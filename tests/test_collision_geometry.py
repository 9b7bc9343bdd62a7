"""Collision avoidance's geometry against coal and finite differences: the broadphase's
segment distances, every pair's distance and witness points, the distance rate's row, the
obstacles' feed-forward, the pair rules and the settings' round trip."""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from constraints import Hole
from constraints.collision import (Box, Capsule, CollisionAvoidance, HalfSpace, Obstacle,
                                   Sphere)
from constraints.collision.avoidance import GJK_TOLERANCE
from constraints.collision.geometry import capsule_geometry, segment_distances
from teleop import load_robot

from strategies import vec3

seeds = st.integers(0, 2**32 - 1)


@pytest.fixture(scope="module")
def dual():
    return load_robot("sda10f_dual")


def obstacles_near(robot, q) -> list[Obstacle]:
    """One obstacle of each kind a few centimetres from the left arm's wrist at ``q``."""
    model = robot.model
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    wrist = data.oMf[model.getFrameId("arm_left_link_5_r")].translation
    return [Sphere(wrist + [0.0, 0.0, 0.12], 0.05, velocity=(0.0, 0.0, -0.1), name="organ"),
            Box(wrist + [0.12, 0.0, 0.0], (0.06, 0.08, 0.1), rpy=(0.3, 0.1, -0.2), name="box"),
            Capsule(wrist + [0.0, 0.13, 0.0], 0.03, 0.2, axis=np.array([1.0, 0.0, 1.0]) / np.sqrt(2),
                    name="bar"),
            HalfSpace(wrist - [0.0, 0.0, 0.1], np.array([0.0, 0.2, 1.0]) / np.hypot(0.2, 1.0),
                      velocity=(0.0, 0.0, 0.05), name="table")]


# -- the broadphase's segment distance ------------------------------------------------------


def point_segment(point: np.ndarray, start: np.ndarray, end: np.ndarray) -> float:
    direction = end - start
    length = float(direction @ direction)
    s = 0.0 if length == 0.0 else float(np.clip((point - start) @ direction / length, 0.0, 1.0))
    return float(np.linalg.norm(point - start - s * direction))


@settings(max_examples=200, deadline=None)
@given(vec3, vec3, vec3, vec3, st.sampled_from(["segments", "first point", "second point",
                                                "parallel"]))
def test_segment_distances_equal_coal(a, b, c, d, case):
    """Every case of the clamped closest points (a point for a segment, parallel ones)
    against coal's capsule distance at zero radius, and a dense sampling's minimum, to
    1e-6 m (a segment shorter than that counts as a point)."""
    if case == "first point":
        b = a.copy()
    elif case == "second point":
        d = c.copy()
    elif case == "parallel":
        d = c + (b - a) * 0.7
    ours = float(segment_distances(a[None], b[None], c[None], d[None])[0])
    samples = np.linspace(0.0, 1.0, 401)
    sampled = min(point_segment(a + s * (b - a), c, d) for s in samples)
    assert ours <= sampled + 1e-6
    assert ours >= sampled - np.linalg.norm(b - a) / 400 - 1e-6
    if np.linalg.norm(b - a) > 1e-3 and np.linalg.norm(d - c) > 1e-3:
        expected = coal_segment_distance(a, b, c, d)
        assert ours == pytest.approx(expected, abs=1e-7)


def coal_segment_distance(a, b, c, d) -> float:
    """coal's distance between two thin capsules on the segments, plus their radii."""
    radius = 1e-4

    def capsule(start, end):
        centre, axis = (start + end) / 2, end - start
        length = float(np.linalg.norm(axis))
        rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis / length).matrix()
        return coal.Capsule(radius, length), coal.Transform3s(rotation, centre)

    (first, first_pose), (second, second_pose) = capsule(a, b), capsule(c, d)
    result = coal.DistanceResult()
    distance = coal.distance(first, first_pose, second, second_pose, coal.DistanceRequest(), result)
    return distance + 2 * radius


# -- distances and witness points against coal ----------------------------------------------


@settings(max_examples=30, deadline=None)
@given(seeds)
def test_rows_distances_and_witnesses_equal_coal(dual, seed):
    """Each row's distance and witness points are coal's for that pair (the robot's
    capsules and boxes against each other and against every obstacle kind)."""
    q = dual.random_configuration(np.random.default_rng(seed))
    avoidance = CollisionAvoidance(dual, obstacles_near(dual, q))
    model, data = dual.model, dual.model.createData()
    pin.computeJointJacobians(model, data, q)
    rows = avoidance.rows(model, data)
    assume(rows.size > 0)
    geometry = capsule_geometry(dual.collision_model)
    geometry_data = geometry.createData()
    pin.updateGeometryPlacements(model, data, geometry, geometry_data)
    bodies = {}
    for index, item in enumerate(geometry.geometryObjects):
        bodies.setdefault(model.frames[item.parentFrame].name, []).append(
            (item.geometry, geometry_data.oMg[index]))
    for obstacle in avoidance.obstacles:
        bodies[obstacle.name] = [(obstacle.shape(), obstacle.pose())]
    for name, distance, (on_first, on_second) in zip(rows.pairs, rows.distances, rows.witnesses):
        first, second = name.split(" | ")
        candidates = [coal_distance(*one, *other) for one in bodies[first] for other in bodies[second]]
        expected, points = min(candidates, key=lambda item: abs(item[0] - distance))
        assert distance == pytest.approx(expected, abs=1e-9 if distance > 0 else 1e-6)
        if distance > 1e-4:
            np.testing.assert_allclose(on_first, points[0], atol=1e-7)
            np.testing.assert_allclose(on_second, points[1], atol=1e-7)
            assert np.linalg.norm(on_first - on_second) == pytest.approx(distance, abs=1e-7)
    assert rows.minimum_distance <= float(np.min(rows.distances))


@settings(max_examples=20, deadline=None)
@given(seeds, st.lists(st.floats(-0.05, 0.05), min_size=3, max_size=3))
def test_an_obstacle_moved_between_two_steps_is_measured_where_it_went(dual, seed, shift):
    """An avoidance that measured the obstacles once, then has them moved (``move_to``),
    gives the rows a fresh avoidance built at the new places gives: the pose it keeps
    for an obstacle not moved is not kept for a moved one."""
    q = dual.random_configuration(np.random.default_rng(seed))
    obstacles = obstacles_near(dual, q)
    avoidance = CollisionAvoidance(dual, obstacles)
    model, data = dual.model, dual.model.createData()
    pin.computeJointJacobians(model, data, q)
    avoidance.rows(model, data)
    for obstacle in obstacles[::2]:
        obstacle.move_to(obstacle.position + np.asarray(shift))
    moved = avoidance.rows(model, data)
    fresh = CollisionAvoidance(dual, obstacles).rows(model, data)
    assert moved.pairs == fresh.pairs
    # coal starts each pair's GJK where it ended the step before: equal to its tolerance
    np.testing.assert_allclose(moved.distances, fresh.distances, rtol=0, atol=GJK_TOLERANCE)
    np.testing.assert_allclose(moved.rows, fresh.rows, rtol=0, atol=1e-6)


def coal_distance(first, first_pose, second, second_pose):
    result = coal.DistanceResult()
    distance = coal.distance(first, coal.Transform3s(first_pose.rotation, first_pose.translation),
                             second, coal.Transform3s(second_pose.rotation, second_pose.translation),
                             coal.DistanceRequest(), result)
    return distance, (result.getNearestPoint1().copy(), result.getNearestPoint2().copy())


@settings(max_examples=30, deadline=None)
@given(seeds)
def test_the_broadphase_keeps_every_pair_within_the_detection_distance(dual, seed):
    """The rows hold exactly the pairs whose coal distance (every pair, no broadphase) is
    below the detection distance, and the minimum over them."""
    q = dual.random_configuration(np.random.default_rng(seed))
    avoidance = CollisionAvoidance(dual, obstacles_near(dual, q))
    model, data = dual.model, dual.model.createData()
    pin.computeJointJacobians(model, data, q)
    rows = avoidance.rows(model, data)
    measured = avoidance.distances(model, data)
    near = sorted(distance for _, distance in measured if distance < avoidance.detection_distance)
    # a penetration's depth comes from coal's EPA, iterative: 1e-6 m between two calls
    np.testing.assert_allclose(sorted(rows.distances), near, atol=1e-6)
    closest = min(distance for _, distance in measured)
    if closest < avoidance.detection_distance:
        assert rows.minimum_distance == pytest.approx(closest, abs=1e-6)


# -- the distance rate's row against finite differences -------------------------------------


def pair_distance(avoidance: CollisionAvoidance, model, q: np.ndarray, name: str,
                  near: float) -> float:
    """The distance at ``q`` of the pair called ``name`` whose distance is nearest ``near``
    (two geometries of one link pair share a name)."""
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    return min((distance for pair, distance in avoidance.distances(model, data) if pair == name),
               key=lambda distance: abs(distance - near))


@settings(max_examples=25, deadline=None)
@given(seeds, seeds)
def test_the_rows_are_the_distance_rates(dual, seed, direction_seed):
    """``row . qd`` is the central finite difference of the pair's distance along ``qd``
    (obstacles at rest), for robot-robot and robot-obstacle pairs alike."""
    rng = np.random.default_rng(seed)
    q = dual.random_configuration(rng)
    obstacles = obstacles_near(dual, q)
    for obstacle in obstacles:
        obstacle.velocity = np.zeros(3)
    avoidance = CollisionAvoidance(dual, obstacles)
    model, data = dual.model, dual.model.createData()
    pin.computeJointJacobians(model, data, q)
    rows = avoidance.rows(model, data)
    apart = np.flatnonzero(rows.distances > 2e-3)  # (a penetration's depth is iterative EPA)
    assume(apart.size > 0)
    qd = np.random.default_rng(direction_seed).normal(size=model.nv)
    step = 1e-6
    for i in apart.tolist():
        name = rows.pairs[i]
        ahead = pair_distance(avoidance, model, pin.integrate(model, q, step * qd), name,
                              rows.distances[i])
        behind = pair_distance(avoidance, model, pin.integrate(model, q, -step * qd), name,
                               rows.distances[i])
        rate = (ahead - behind) / (2 * step)
        assert rows.rows[i] @ qd == pytest.approx(rate, abs=1e-5 * (1 + np.linalg.norm(qd)))


def test_a_moving_obstacle_is_fed_forward(dual):
    """The bound of a robot-obstacle row gains ``n . v``: with the robot still, the
    distance's rate is ``-n . v`` (finite differences of the moved obstacle)."""
    q = dual.q_home.copy()
    velocity = np.array([0.02, -0.05, -0.1])
    sphere = obstacles_near(dual, q)[0]
    sphere.velocity = velocity
    avoidance = CollisionAvoidance(dual, [sphere], self_collision=False)
    model, data = dual.model, dual.model.createData()
    pin.computeJointJacobians(model, data, q)
    rows = avoidance.rows(model, data)
    assert rows.size > 0
    i = int(np.argmin(rows.distances))
    name = rows.pairs[i]
    centre, step = sphere.center.copy(), 1e-6
    sphere.move_to(centre + step * velocity, velocity)
    ahead = pair_distance(avoidance, model, q, name, rows.distances[i])
    sphere.move_to(centre - step * velocity, velocity)
    behind = pair_distance(avoidance, model, q, name, rows.distances[i])
    rate = (ahead - behind) / (2 * step)
    damper = -avoidance.gain * (rows.distances[i] - avoidance.safety_distance)
    # still robot: 0 >= damper - rate, so the bound minus the damper is minus the rate
    assert rows.lower[i] - damper == pytest.approx(-rate, abs=1e-6)


# -- the pairs ---------------------------------------------------------------------------


def test_pairs_skip_one_body_and_parent_child_and_follow_the_lists(dual):
    model = dual.model
    avoidance = CollisionAvoidance(dual)
    joint_of = {frame.name: frame.parentJoint for frame in model.frames}
    for first, second in avoidance.pairs:
        a, b = joint_of[first], joint_of[second]
        assert a != b and model.parents[a] != b and model.parents[b] != a
    assert ("arm_left_link_4_u", "arm_right_link_4_u") in avoidance.pairs
    trimmed = CollisionAvoidance(dual, disabled_pairs=[("arm_right_link_4_u", "arm_left_link_4_u")])
    assert ("arm_left_link_4_u", "arm_right_link_4_u") not in trimmed.pairs
    assert len(trimmed.pairs) < len(avoidance.pairs)
    extended = CollisionAvoidance(dual, extra_pairs=[("arm_left_link_3_e", "arm_left_link_4_u")])
    assert ("arm_left_link_3_e", "arm_left_link_4_u") in extended.pairs
    # every pair kept is clear of the safety distance at home
    data = model.createData()
    pin.forwardKinematics(model, data, dual.q_home)
    assert min(distance for _, distance in avoidance.distances(model, data)) \
        > avoidance.safety_distance


def test_the_instrument_in_a_port_is_not_an_obstacle_of_the_body(dual):
    """A body obstacle around a hole: the holed link and the links after it are not paired
    with it; the other links are."""
    model = dual.model
    data = model.createData()
    pin.forwardKinematics(model, data, dual.q_home)
    pin.updateFramePlacements(model, data)
    link = dual.constrained_links[0]
    hole = Hole.on_link(dual, dual.q_home, distance=0.05, link=link)
    body = Sphere(hole.position - [0.0, 0.0, 0.1], 0.1, name="body")
    avoidance = CollisionAvoidance(dual, [body], self_collision=False)
    before = {pair for pair in avoidance.pairs}
    avoidance.set_ports([hole])
    after = set(avoidance.pairs)
    removed = before - after
    after_port = {"arm_left_link_5_r", "arm_left_link_6_b", "arm_left_link_7_t"}
    assert removed and {first for first, _ in removed} <= after_port
    assert all(second == "body" for _, second in removed)
    assert any(first.endswith("link_1_s") for first, _ in after)


# -- settings and obstacles: description and bad input ----------------------------------------


@settings(max_examples=30, deadline=None)
@given(vec3, vec3, st.floats(0.01, 0.5), st.floats(0.0, 0.3))
def test_obstacles_round_trip_through_their_dicts(centre, direction, radius, length):
    assume(np.linalg.norm(direction) > 0.1)
    direction = direction / np.linalg.norm(direction)
    for obstacle in (Sphere(centre, radius), Box(centre, (radius, 2 * radius, 0.1), rpy=direction),
                     Capsule(centre, radius, length, axis=direction, velocity=direction),
                     HalfSpace(centre, direction, name="wall")):
        again = Obstacle.from_dict(obstacle.to_dict())
        assert type(again) is type(obstacle) and again.to_dict().keys() == obstacle.to_dict().keys()
        for name, value in obstacle.to_dict().items():  # a unit vector is normalised again
            if isinstance(value, list):
                np.testing.assert_allclose(again.to_dict()[name], value, rtol=0, atol=1e-15)
            else:
                assert again.to_dict()[name] == value
        pose, shape = again.pose(), again.shape()
        if not isinstance(shape, coal.Halfspace):  # the shape's own centre is the reference point
            np.testing.assert_allclose(pose.translation, centre)


def test_settings_round_trip(dual):
    avoidance = CollisionAvoidance(dual, [Sphere((0.5, 0.0, 1.0), 0.1)], safety_distance=0.01,
                                   detection_distance=0.08, approach_speed=0.3,
                                   disabled_pairs=[("arm_left_link_4_u", "arm_right_link_4_u")])
    again = CollisionAvoidance.from_dict(dual, avoidance.to_dict())
    assert again.to_dict() == avoidance.to_dict()
    assert again.pairs == avoidance.pairs


@pytest.mark.parametrize("data, message", [
    ({"kind": "cube", "center": [0, 0, 0]}, "unknown obstacle kind 'cube'"),
    ({"kind": "sphere", "center": [0, 0, 0]}, "needs the field 'radius'"),
    ({"kind": "sphere", "center": [0, 0, 0], "radius": -1}, "radius must be > 0"),
    ({"kind": "box", "center": [0, 0, 0], "size": [1, 0, 1]}, "size must be three edges"),
    ({"kind": "halfspace", "center": [0, 0, 0], "normal": [0, 0, 0]}, "normal"),
    ({"kind": "sphere", "center": [0, "x", 0], "radius": 1}, "center"),
    ({"kind": "sphere", "center": [0, 0, 0], "radius": 1, "colour": 1}, "unknown field 'colour'"),
])
def test_bad_obstacles_are_refused_by_name(data, message):
    with pytest.raises(ValueError, match=message):
        Obstacle.from_dict(data)


@pytest.mark.parametrize("keywords, message", [
    ({"safety_distance": -0.001}, "safety_distance must be >= 0"),
    ({"safety_distance": 0.05, "detection_distance": 0.05}, "must exceed safety_distance"),
    ({"approach_speed": 0.0}, "approach_speed must be > 0"),
    ({"disabled_pairs": [("arm_left_link_4_u",)]}, "pairs of two link names"),
    ({"extra_pairs": [("arm_left_link_4_u", "elbow")]}, "'elbow', which is not a link"),
    ({"obstacles": ["sphere"]}, "must be a Sphere, Box, Capsule or HalfSpace"),
])
def test_bad_settings_are_refused_by_name(dual, keywords, message):
    obstacles = keywords.pop("obstacles", ())
    with pytest.raises(ValueError, match=message):
        CollisionAvoidance(dual, obstacles, **keywords)


def test_an_unstable_damper_and_another_robot_are_refused(dual):
    avoidance = CollisionAvoidance(dual, approach_speed=10.0, detection_distance=0.01)
    with pytest.raises(ValueError, match="unstable at 1000 Hz"):
        avoidance.check(dual.model, 1e-3)
    # the rate with the response time: 1 / (0.005 / 10 + 0.0004) = 1111 1/s
    late = CollisionAvoidance(dual, approach_speed=10.0, detection_distance=0.01,
                              response_time=4e-4)
    with pytest.raises(ValueError, match=r"rate K = xi / \(d_i - d_s \+ xi tau\) = 1111.11 1/s "
                       r"\(tau = response_time 0.0004 s\) is unstable at 1000 Hz"):
        late.check(dual.model, 1e-3)
    CollisionAvoidance(dual, approach_speed=10.0, detection_distance=0.01,
                       response_time=6e-4).check(dual.model, 1e-3)  # 1 / 1.1 ms: stable
    with pytest.raises(ValueError, match="another robot"):
        CollisionAvoidance(dual).check(load_robot("sda10f").model, 1e-3)
