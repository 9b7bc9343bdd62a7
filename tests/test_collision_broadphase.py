"""The obstacles' broadphase (constraints/collision/broadphase.py) leaves out no obstacle
that can come near: its boxes against a brute-force comparison of every box, and the
collision rows of an avoidance with many obstacles against every pair measured by coal
(pinocchio.computeDistances), at random configurations and obstacle fields."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings, strategies as st

from constraints.collision import CollisionAvoidance
from constraints.collision.avoidance import BOUNDING_MARGIN
from constraints.collision.broadphase import ObstacleBoxes, capsule_boxes
from constraints.collision.obstacles import Box, Capsule, HalfSpace, Sphere
from teleop import load_robot


@given(seed=st.integers(0, 2**32 - 1), count=st.integers(0, 300),
       spread=st.floats(0.1, 10.0), halfspaces=st.integers(0, 2))
def test_the_boxes_met_are_those_a_brute_force_comparison_finds(seed, count, spread,
                                                                 halfspaces):
    rng = np.random.default_rng(seed)
    starts = rng.uniform(-spread, spread, (count, 3))
    ends = starts + rng.normal(0.0, 0.3, (count, 3)) * (rng.random((count, 1)) < 0.5)
    radii = rng.uniform(0.0, 0.5, count)
    radii[rng.choice(count, min(count, halfspaces), replace=False)] = np.inf
    boxes = ObstacleBoxes(starts, ends, radii)
    lower, upper = capsule_boxes(starts, ends, radii)
    for _ in range(5):
        low = rng.uniform(-spread, spread, 3)
        high = low + rng.uniform(0.0, spread, 3)
        brute = np.all((lower <= high) & (upper >= low), axis=1) | ~np.isfinite(radii)
        np.testing.assert_array_equal(boxes.near(low, high), brute)


@pytest.fixture(scope="module")
def robot():
    return load_robot("ur5_instrument")


def unit(vector: np.ndarray) -> np.ndarray:
    return vector / np.linalg.norm(vector)


def field(rng: np.random.Generator, count: int) -> list:
    """``count`` obstacles of every kind scattered over 2 m around the arm, a floor."""
    kinds = [lambda c: Sphere(c, rng.uniform(0.01, 0.1)),
             lambda c: Box(c, rng.uniform(0.02, 0.3, 3).tolist(), rpy=rng.uniform(-3, 3, 3).tolist()),
             lambda c: Capsule(c, rng.uniform(0.01, 0.05), rng.uniform(0.05, 0.4),
                               axis=unit(rng.normal(size=3)).tolist())]
    obstacles = [kinds[k % 3](rng.uniform([-1.0, -1.0, -0.2], [1.0, 1.0, 1.2]).tolist())
                 for k in range(count - 1)]
    return obstacles + [HalfSpace([0.0, 0.0, -0.3], [0.0, 0.0, 1.0])]


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_the_rows_are_those_of_every_pair_measured(robot, seed):
    rng = np.random.default_rng(seed)
    obstacles = field(rng, 100)
    avoidance = CollisionAvoidance(robot, obstacles, self_collision=False,
                                   detection_distance=0.1, safety_distance=0.005)
    lower, upper = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    q = np.clip(robot.q_home + rng.normal(0.0, 0.5, robot.model.nq), lower, upper)
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    rows = avoidance.rows(robot.model, data)
    # the reference: every pair measured by coal, the broadphase's geometry model reused
    geometry, geometry_data = avoidance._geometry, avoidance._geometry_data
    pin.updateGeometryPlacements(robot.model, data, geometry, geometry_data)
    pin.computeDistances(geometry, geometry_data)
    near = sorted((f"{avoidance._names[pair.first]} | {avoidance._names[pair.second]}",
                   result.min_distance)
                  for pair, result in zip(geometry.collisionPairs, geometry_data.distanceResults)
                  if result.min_distance < avoidance.detection_distance)
    got = sorted(zip(rows.pairs, rows.distances))  # (a link may have several geometries)
    assert [name for name, _ in got] == [name for name, _ in near], (got, near)
    np.testing.assert_allclose([d for _, d in got], [d for _, d in near], rtol=0, atol=1e-9)


def rows_in_order(avoidance: CollisionAvoidance, model: pin.Model, data: pin.Data,
                  close_last_step: bool):
    """``avoidance.rows`` with its measuring order chosen (coal first: a pair was closer
    than ``d_i - BOUNDING_MARGIN`` at the last step; the capsules first: none was)."""
    avoidance._close_last_step = close_last_step
    return avoidance.rows(model, data)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_either_measuring_order_gives_the_same_rows(robot, seed):
    """The pairs that count (their bounding capsules within d_i) are the same whichever
    pairs coal measures first: the rows, the smallest distance and its pair, to the bit.
    Spheres are put at d_i less and plus half the margin and at d_i less twice it from
    robot capsules (the pairs whose capsules _counted measures), each in half the draws,
    beside a field of every kind and a floor (a box's bounding capsule reaches beyond
    it: a pair whose capsules come within d_i may be farther, and then, with no pair that
    close, be the smallest distance). Each order on an avoidance of its own, measured once
    (coal's answer for a box depends, to rounding, on what it measured the pair at
    before)."""
    rng = np.random.default_rng(seed)
    detection = 0.1
    lower, upper = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    q = np.clip(robot.q_home + rng.normal(0.0, 0.5, robot.model.nq), lower, upper)
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    probe = CollisionAvoidance(robot, [], self_collision=False, detection_distance=detection)
    starts, ends = probe._update(robot.model, data)
    placed = []
    for gap in (detection - BOUNDING_MARGIN / 2, detection + BOUNDING_MARGIN / 2,
                detection - 2 * BOUNDING_MARGIN):
        if rng.random() < 0.5:
            continue
        body = int(rng.integers(probe._robot_count))
        axis = ends[body] - starts[body]
        # normal to the capsule's axis from its middle: the sphere's nearest point on the
        # capsule is on its side, at the gap asked
        side = rng.normal(size=3)
        if np.linalg.norm(axis) > 0.0:
            side -= axis * (side @ axis) / (axis @ axis)
        radius = rng.uniform(0.01, 0.05)
        centre = ((starts[body] + ends[body]) / 2
                  + unit(side) * (probe._radii[body] + radius + gap))
        placed.append(Sphere(centre.tolist(), radius))
    obstacles = placed + field(rng, 60)
    coal_first, capsules_first = (
        rows_in_order(CollisionAvoidance(robot, obstacles, self_collision=False,
                                         detection_distance=detection),
                      robot.model, data, close)
        for close in (True, False))
    assert coal_first.pairs == capsules_first.pairs
    for name in ("rows", "lower", "distances", "witnesses"):
        np.testing.assert_array_equal(getattr(coal_first, name), getattr(capsules_first, name))
    assert coal_first.minimum_distance == capsules_first.minimum_distance
    assert coal_first.closest_pair == capsules_first.closest_pair


def test_the_capsules_decide_where_no_pair_is_that_close(robot):
    """_counted, on the pairs the boxes let through at a drawn configuration with 100
    obstacles: with the bodies at their capsules' gaps (some closer than d_i less the
    margin), the pairs counted are those whose capsules come within d_i; with every body
    farther than d_i less the margin (those whose capsules come within d_i put beyond
    d_i), still those: the capsules decide every pair, or the smallest distance would be
    taken over none of them."""
    rng = np.random.default_rng(5)
    avoidance = CollisionAvoidance(robot, field(rng, 100), self_collision=False,
                                   detection_distance=0.1)
    q = np.clip(robot.q_home + rng.normal(0.0, 0.5, robot.model.nq),
                robot.model.lowerPositionLimit, robot.model.upperPositionLimit)
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    starts, ends = avoidance._update(robot.model, data)
    boxed = avoidance._boxed_pairs(starts, ends)
    gaps = avoidance._capsule_gaps(starts, ends, boxed)
    near = gaps < avoidance.detection_distance
    assert near.any() and not near.all()
    assert (gaps < avoidance.detection_distance - BOUNDING_MARGIN).any()
    np.testing.assert_array_equal(avoidance._counted(starts, ends, boxed, gaps.copy()), near)
    farther = np.where(near, avoidance.detection_distance + 0.01, gaps + 0.01)
    np.testing.assert_array_equal(avoidance._counted(starts, ends, boxed, farther), near)
