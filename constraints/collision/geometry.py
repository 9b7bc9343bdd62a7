"""The robot's collision geometry and the pairs worth checking (docs/design.md 18.1).

From the URDF's collision elements (Pinocchio's ``GeometryModel``): cylinders become
capsules of the same radius and axis length (a cylinder's distance is not smooth at its
rims, a capsule's is, and a capsule adds the rounded ends a joint housing has); meshes
become their convex hulls; spheres and boxes stay. The self-collision pairs are every two
geometries on links that are neither the same rigid body nor parent and child, that are
farther apart than the safety distance at the robot's home configuration, and that no
disable list names (an SRDF's ``disable_collisions``), plus any pair the user adds.
"""

from __future__ import annotations

from collections.abc import Iterable, Set

import coal
import numpy as np
import pinocchio as pin

from ..validation import short_repr

#: a link pair as two link names, in either order
LinkPair = tuple[str, str]


def capsule_geometry(collision_model: pin.GeometryModel) -> pin.GeometryModel:
    """A copy of ``collision_model`` with capsules for cylinders and convex hulls for meshes."""
    result = pin.GeometryModel()
    for item in collision_model.geometryObjects:
        shape = item.geometry
        if isinstance(shape, coal.Cylinder):
            shape = coal.Capsule(shape.radius, 2.0 * shape.halfLength)
        elif isinstance(shape, coal.BVHModelBase):
            shape.buildConvexHull(True, "Qt")
            shape = shape.convex
        result.addGeometryObject(pin.GeometryObject(
            item.name, item.parentJoint, item.parentFrame, item.placement, shape))
    return result


def link_of(model: pin.Model, item: pin.GeometryObject) -> str:
    """The name of the link (body frame) a geometry is attached to."""
    return model.frames[item.parentFrame].name


def adjacent(model: pin.Model, first: int, second: int) -> bool:
    """Whether joints ``first`` and ``second`` carry one rigid body or a parent and its child."""
    return (first == second or model.parents[first] == second
            or model.parents[second] == first)


def pair_key(first: str, second: str) -> frozenset[str]:
    """A link pair, without order."""
    return frozenset((first, second))


def link_pairs(pairs: Iterable, what: str) -> set[frozenset[str]]:
    """``pairs`` (a list, tuple or set of two link names each) as unordered keys, else
    ``ValueError`` naming ``what``."""
    if not isinstance(pairs, (list, tuple, set, frozenset)):
        raise ValueError(f"{what} must be a list of link pairs, got {short_repr(pairs)}")
    keys = set()
    for pair in pairs:
        if (isinstance(pair, str) or not isinstance(pair, (list, tuple)) or len(pair) != 2
                or not all(isinstance(name, str) for name in pair)):
            raise ValueError(f"{what} must be pairs of two link names, got {short_repr(pair)}")
        keys.add(pair_key(*pair))
    return keys


def check_links(model: pin.Model, keys: set[frozenset[str]], what: str) -> None:
    """Every link named in ``keys`` exists in ``model``, else ``ValueError``."""
    frames = {frame.name for frame in model.frames}
    for key in keys:
        for name in key:
            if name not in frames:
                raise ValueError(f"{what} names {name!r}, which is not a link of the robot")


def self_collision_pairs(model: pin.Model, geometry: pin.GeometryModel, q_home: np.ndarray,
                         safety_distance: float, disabled: Set[frozenset[str]] = frozenset(),
                         extra: Set[frozenset[str]] = frozenset()) -> list[tuple[int, int]]:
    """Geometry index pairs ``(i, j)``, ``i < j``, checked for self-collision.

    A pair is kept when its links are neither one rigid body nor parent and child, it is
    farther apart than ``safety_distance`` at ``q_home`` and ``disabled`` does not name
    its links; a pair of links in ``extra`` is kept whatever the rest says (not on one
    rigid body).
    """
    data = model.createData()
    geometry_data = geometry.createData()
    pin.updateGeometryPlacements(model, data, geometry, geometry_data, q_home)
    objects = geometry.geometryObjects
    pairs = []
    for i in range(len(objects)):
        for j in range(i + 1, len(objects)):
            first, second = objects[i], objects[j]
            if first.parentJoint == second.parentJoint:
                continue
            key = pair_key(link_of(model, first), link_of(model, second))
            if key in extra:
                pairs.append((i, j))
                continue
            if key in disabled or adjacent(model, first.parentJoint, second.parentJoint):
                continue
            if shape_distance(first.geometry, geometry_data.oMg[i],
                              second.geometry, geometry_data.oMg[j]) > safety_distance:
                pairs.append((i, j))
    return pairs


def shape_distance(first: coal.CollisionGeometry, first_pose: pin.SE3,
                   second: coal.CollisionGeometry, second_pose: pin.SE3) -> float:
    """The signed distance (m) between two posed coal shapes."""
    request, result = coal.DistanceRequest(), coal.DistanceResult()
    return coal.distance(first, coal.Transform3s(first_pose.rotation, first_pose.translation),
                         second, coal.Transform3s(second_pose.rotation, second_pose.translation),
                         request, result)


def bounding_segment(shape: coal.CollisionGeometry,
                     placement: pin.SE3) -> tuple[np.ndarray, np.ndarray, float]:
    """A capsule holding ``shape`` posed at ``placement``: its segment's two ends (in the
    parent frame) and its radius (m), for the broadphase. A capsule is its own; a sphere a
    point; a box the segment along its longest edge with the radius of the other two's
    half-diagonal; anything else the sphere of its bounding box. A half-space has none
    (infinite radius: the broadphase tests its plane instead)."""
    if isinstance(shape, coal.Halfspace):
        return placement.translation.copy(), placement.translation.copy(), float("inf")
    if isinstance(shape, coal.Capsule):
        half = placement.rotation[:, 2] * shape.halfLength
        return placement.translation - half, placement.translation + half, float(shape.radius)
    if isinstance(shape, coal.Sphere):
        return placement.translation.copy(), placement.translation.copy(), float(shape.radius)
    if isinstance(shape, coal.Box):
        half_sides = np.asarray(shape.halfSide, dtype=float)
        longest = int(np.argmax(half_sides))
        half = placement.rotation[:, longest] * half_sides[longest]
        radius = float(np.linalg.norm(np.delete(half_sides, longest)))
        return placement.translation - half, placement.translation + half, radius
    shape.computeLocalAABB()
    centre = placement.act(np.asarray(shape.aabb_center))
    return centre, centre.copy(), float(shape.aabb_radius)


def segment_distances(first_start: np.ndarray, first_end: np.ndarray,
                      second_start: np.ndarray, second_end: np.ndarray) -> np.ndarray:
    """The distances (n,) between n pairs of segments, each given by its ends (n, 3)
    (the clamped closest points of Ericson, *Real-Time Collision Detection*, 5.1.9), to
    1e-6 m: a segment shorter than that counts as its first end."""
    d1, d2 = first_end - first_start, second_end - second_start
    r = first_start - second_start
    # the five dot products d1.d1, d2.d2, d2.r, d1.r, d1.d2 in three numpy calls, not ten
    # (each row's three products summed as (x * y).sum(1) sums them: the same bits, 4 us less)
    a, e, f, c, b = (np.array([d1, d2, d2, d1, d1]) * np.array([d1, d2, r, r, d2])).sum(2)
    tiny = 1e-12
    # a point for a segment: its length's square floored at ``tiny`` and the projection
    # onto it then clamped to its one end (every division is by a positive number)
    a_safe, e_safe = np.maximum(a, tiny), np.maximum(e, tiny)
    s = unit_clamp((b * f - c * e) / np.maximum(a * e - b * b, tiny))
    t = (b * s + f) / e_safe
    s_first = unit_clamp(-c / a_safe)  # the first segment's point nearest the second's start
    s = np.where(t < 0.0, s_first, np.where(t > 1.0, unit_clamp((b - c) / a_safe), s))
    s = np.where(e > tiny, s, s_first)
    t = unit_clamp(t)
    gap = r + d1 * s[:, None] - d2 * t[:, None]
    return np.sqrt((gap * gap).sum(1))


def unit_clamp(values: np.ndarray) -> np.ndarray:
    """``values`` clamped to [0, 1] (``np.minimum(np.maximum(...))``: several times faster
    than ``np.clip`` on short arrays)."""
    return np.minimum(np.maximum(values, 0.0), 1.0)
