"""The geometry the view draws with: rotations as viser quaternions, line segments of
rings and arrows, and how far a link's meshes reach from its axis (rings and collars go
outside them)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import trimesh

from teleop.robots import Robot


def wxyz_of(rotation: np.ndarray) -> tuple[float, float, float, float]:
    quaternion = pin.Quaternion(rotation)
    return quaternion.w, quaternion.x, quaternion.y, quaternion.z


def wxyz_from_z(direction: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) of a rotation taking +z to ``direction``."""
    rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), np.asarray(direction, float))
    return np.array([rotation.w, rotation.x, rotation.y, rotation.z])


def _perpendicular(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def ring_segments(center: np.ndarray, axis: np.ndarray, radius: float = 0.015, n: int = 32) -> np.ndarray:
    """Line segments (n, 2, 3) of a circle around ``axis`` through ``center``."""
    u, v = _perpendicular(np.asarray(axis, dtype=float))
    angles = np.linspace(0.0, 2.0 * np.pi, n + 1)
    points = center + radius * (np.outer(np.cos(angles), u) + np.outer(np.sin(angles), v))
    return np.stack([points[:-1], points[1:]], axis=1)


def arrow_segments(start: np.ndarray, direction: np.ndarray, length: float) -> np.ndarray:
    """Line segments (5, 2, 3) of an arrow from ``start`` along the unit ``direction``."""
    tip = start + length * direction
    u, v = _perpendicular(direction)
    head = 0.25 * length
    barbs = [tip - head * direction + 0.5 * head * side for side in (u, -u, v, -v)]
    return np.array([[start, tip], *[[tip, barb] for barb in barbs]])


def _geometry_points(geometry) -> np.ndarray:
    """Points (n, 3) on one geometry in its own frame: a mesh's vertices; circles on a
    cylinder or capsule (axis z), points on a sphere; else a 5x5x5 grid filling its
    bounding box (a box...)."""
    kind = type(geometry).__name__
    angles = np.linspace(0.0, 2.0 * np.pi, 16, endpoint=False)
    circle = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    if kind in ("Cylinder", "Capsule"):
        half = geometry.halfLength + (geometry.radius if kind == "Capsule" else 0.0)
        return np.concatenate([geometry.radius * circle + [0.0, 0.0, z]
                               for z in np.linspace(-half, half, 9)])
    if kind == "Sphere":
        return np.concatenate([geometry.radius * np.sin(polar) * circle
                               + [0.0, 0.0, geometry.radius * np.cos(polar)]
                               for polar in np.linspace(0.0, np.pi, 9)])
    if hasattr(geometry, "vertices"):
        try:
            vertices = np.asarray(geometry.vertices(), dtype=float)
            if vertices.ndim == 2 and vertices.shape[1] == 3 and len(vertices):
                return vertices
        except (AttributeError, RuntimeError, TypeError):
            pass
    try:
        geometry.computeLocalAABB()
        low = np.asarray(geometry.aabb_local.min_, dtype=float)
        high = np.asarray(geometry.aabb_local.max_, dtype=float)
    except (AttributeError, RuntimeError):
        return np.zeros((0, 3))
    if not (np.isfinite(low).all() and np.isfinite(high).all()):
        return np.zeros((0, 3))
    grid = np.linspace(0.0, 1.0, 5)
    weights = np.stack(np.meshgrid(grid, grid, grid, indexing="ij"), axis=-1).reshape(-1, 3)
    return low + weights * (high - low)


@dataclass(frozen=True)
class LinkProfile:
    """Where a link's geometry (visual and collision) is around an axis through the link
    frame's origin: per point, its coordinate along the axis and its distance from it
    (link frame, m). A ring drawn around the axis at ``s`` must be wider than
    :meth:`radius_at` ``s`` to be seen outside the link's mesh."""

    along: np.ndarray
    radial: np.ndarray

    #: half the slab of the link (m, along the axis) a ring at ``s`` must clear
    SLAB = 0.03

    @classmethod
    def of(cls, robot: Robot, link: str | None, axis=None) -> "LinkProfile":
        """The profile of ``link`` around ``axis`` (default: its instrument axis
        ``robot.link_axes[link]``, else the link frame's z); empty without geometry."""
        empty = cls(np.zeros(0), np.zeros(0))
        model = robot.model
        if link is None or not model.existFrame(link):
            return empty
        frame_id = model.getFrameId(link)
        frame = model.frames[frame_id]
        axis = np.asarray(robot.link_axes.get(link, (0.0, 0.0, 1.0)) if axis is None else axis,
                          dtype=float)
        axis = axis / np.linalg.norm(axis)
        pieces = []
        for geometry_model in (robot.visual_model, robot.collision_model):
            for geometry_object in getattr(geometry_model, "geometryObjects", ()):
                if geometry_object.parentFrame != frame_id:
                    continue
                in_link = frame.placement.actInv(geometry_object.placement)
                local = _geometry_points(geometry_object.geometry)
                if len(local):
                    pieces.append(local @ in_link.rotation.T + in_link.translation)
        if not pieces:
            return empty
        points = np.concatenate(pieces)
        along = points @ axis
        radial = np.linalg.norm(points - np.outer(along, axis), axis=1)
        return cls(along, radial)

    def radius_at(self, s: float | None = None) -> float:
        """How far the geometry reaches from the axis within :attr:`SLAB` of ``s`` (the
        whole link when ``s`` is None or no geometry is there); 0 without geometry."""
        if not self.radial.size:
            return 0.0
        if s is not None:
            near = np.abs(self.along - s) <= self.SLAB
            if np.any(near):
                return float(self.radial[near].max())
        return float(self.radial.max())


def reach_from_axis(robot: Robot, link: str | None) -> float:
    """How far ``link``'s geometry reaches from its instrument axis (0 without one)."""
    return LinkProfile.of(robot, link).radius_at()


#: a ring is this much wider than the geometry it goes around (ratio, and m)
RING_MARGIN = (1.1, 0.005)
MIN_RING_RADIUS = 0.015  # m


def ring_around(radius: float, minimum: float = MIN_RING_RADIUS) -> float:
    """A ring's radius around geometry reaching ``radius`` from the axis: outside it."""
    return max(minimum, RING_MARGIN[0] * radius + RING_MARGIN[1])


def _link_extent(robot: Robot, link: str) -> float:
    """Half the largest horizontal size of ``link``'s visual geometry (0 when it has none)."""
    if not robot.model.existFrame(link):
        return 0.0
    frame_id = robot.model.getFrameId(link)
    extents = []
    for geometry_object in robot.visual_model.geometryObjects:
        if geometry_object.parentFrame != frame_id:
            continue
        try:
            geometry_object.geometry.computeLocalAABB()
            size = np.asarray(geometry_object.geometry.aabb_local.max_) \
                - np.asarray(geometry_object.geometry.aabb_local.min_)
        except (AttributeError, RuntimeError):
            continue
        extents.append(0.5 * float(np.max(size[:2])))
    return max(extents, default=0.0)


#: the square a flat geometry is drawn as: this wide (m), or twice its link's size (a wall
#: beside a mobile base spans the base)
SQUARE_SIZE = 0.3


def square_size(robot: Robot, link: str) -> float:
    """The side (m) of the square a flat geometry on ``link`` is drawn as."""
    return max(SQUARE_SIZE, 4.0 * _link_extent(robot, link))


def shape_mesh(shape) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and triangles (m, 3) of a coal shape in its own frame: a capsule,
    sphere, box or cylinder as itself; a convex hull or mesh from its points' hull; any
    other shape as its bounding box."""
    kind = type(shape).__name__
    if kind == "Capsule":
        mesh = trimesh.creation.capsule(height=2.0 * shape.halfLength, radius=shape.radius,
                                        count=[16, 16])
    elif kind == "Sphere":
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=shape.radius)
    elif kind == "Box":
        mesh = trimesh.creation.box(extents=2.0 * np.asarray(shape.halfSide))
    elif kind == "Cylinder":
        mesh = trimesh.creation.cylinder(radius=shape.radius, height=2.0 * shape.halfLength,
                                         sections=16)
    else:
        points = _geometry_points(shape)
        mesh = trimesh.convex.convex_hull(points) if len(points) >= 4 else \
            trimesh.creation.box(extents=(0.01, 0.01, 0.01))
    return np.asarray(mesh.vertices, dtype=np.float32), np.asarray(mesh.faces, dtype=np.uint32)
