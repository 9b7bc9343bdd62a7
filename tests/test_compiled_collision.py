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

import coal
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from constraints.collision import Box, Capsule, CollisionAvoidance, HalfSpace, Sphere
from constraints.collision.primitives import PRIMITIVE_KINDS
from controllers import CJMController
from controllers.cjm._step import shape_distance
from teleop.experiments.bench import close_arms
from teleop.robots import load_robot
from test_collision_cjm import TRANSLATION, collision_rounding_bound, push_together

#: coal's distance is exact to rounding for spheres and capsules (closed forms) and stops
#: its GJK / EPA at a relative tolerance of 1e-6 (``DistanceRequest``'s default) for a
#: box: the distances here (sizes and gaps of 0.01-0.5 m) agree to 1e-6 times their scale.
#: The witness points and normals follow the distance: 1e-5 (m, or 1 for a normal).
DISTANCE_TOLERANCE = 1e-6
WITNESS_TOLERANCE = 1e-5
#: a witness point's distance to its own body's surface, computed here (rounding on 1 m)
SURFACE_TOLERANCE = 1e-9
SETTINGS = settings(max_examples=300, deadline=None)
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
        return kind, np.array([draw(sizes), draw(st.floats(0.0, 0.2)), 0.0])
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
    coal.distance(coal_shape(*first), coal.Transform3s(first_pose.rotation, first_pose.translation),
                  coal_shape(*second), coal.Transform3s(second_pose.rotation, second_pose.translation),
                  request, result)
    return result


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
    scale = 1.0
    assert abs(distance - reference.min_distance) <= DISTANCE_TOLERANCE * scale, \
        (distance, reference.min_distance)
    assert abs(np.linalg.norm(normal) - 1.0) <= 1e-12
    if distance > 0.0:
        # the witness points are on their bodies, ``distance`` apart along the normal
        assert abs(surface_distance(*first, first_pose, on_first)) <= SURFACE_TOLERANCE
        assert abs(surface_distance(*second, second_pose, on_second)) <= SURFACE_TOLERANCE
        np.testing.assert_allclose(on_first - on_second, distance * normal, rtol=0, atol=1e-12)
        # the normal of two separated convex bodies is unique: coal's, negated
        np.testing.assert_allclose(normal, -np.asarray(reference.normal), rtol=0, atol=WITNESS_TOLERANCE)
        if unique_closest_points(first, second, first_pose, second_pose):
            np.testing.assert_allclose(on_first, reference.getNearestPoint1(), rtol=0, atol=WITNESS_TOLERANCE)
            np.testing.assert_allclose(on_second, reference.getNearestPoint2(), rtol=0, atol=WITNESS_TOLERANCE)
    else:
        # penetrating: each witness point is its body's deepest point along the normal,
        # inside (or on) the other body, and the normal separates them by the depth
        assert surface_distance(*first, first_pose, on_first) <= SURFACE_TOLERANCE
        assert surface_distance(*second, second_pose, on_second) <= SURFACE_TOLERANCE
        assert normal @ (on_first - on_second) <= distance + 1e-12 or second[0] == "halfspace"
