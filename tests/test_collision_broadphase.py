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
