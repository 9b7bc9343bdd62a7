"""Obstacles in the world: spheres, boxes, capsules and half-spaces (docs/design.md 18.2).

An obstacle is a rigid shape the robot's links keep :attr:`CollisionAvoidance.safety_distance`
away from: the patient's body, a table, a wall. Like a constraint it describes itself: its
``kind``, :meth:`Obstacle.to_dict` / :meth:`Obstacle.from_dict` (the kinds are in
:data:`OBSTACLE_TYPES`), its world reference point (:attr:`Obstacle.position`, moved by
:meth:`Obstacle.move_to` with a velocity the avoidance rows feed forward), its coal shape
and world pose (:meth:`Obstacle.shape`, :meth:`Obstacle.pose`) and what a view draws
(:meth:`Obstacle.geometry`).
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import coal
import numpy as np
import pinocchio as pin

from ..limits import MAX_OBSTACLE_SIZE_M, MAX_POSITION_M, MAX_SPEED_M_S
from ..validation import as_number, as_unit_vector, as_vector, short_repr
from .primitives import primitive

#: ``kind -> type`` of every obstacle, in the order messages and the UI list them
OBSTACLE_TYPES: dict[str, type["Obstacle"]] = {}


@dataclass(frozen=True)
class ObstacleGeometry:
    """What a view draws of one obstacle, in the world frame (m).

    ``shape`` is the kind's drawing (``"sphere"``, ``"box"``, ``"capsule"``,
    ``"halfspace"``); ``rotation`` (3 x 3) turns the shape's own axes into the world's
    (a capsule's and a half-space's axis is the local z, a half-space's allowed side
    its +z); ``dimensions``: the sphere's and capsule's radius, the capsule's length, the
    box's three edges; ``velocity``: the world velocity fed forward.
    """

    kind: str
    name: str
    shape: str
    center: np.ndarray
    rotation: np.ndarray
    dimensions: dict[str, object]
    velocity: np.ndarray
    color: tuple[int, int, int]
    label: str


def rotation_to(axis: np.ndarray) -> np.ndarray:
    """A rotation whose third column is the unit ``axis`` (the shortest turn from z)."""
    return pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), axis).matrix()


class Obstacle(ABC):
    """A rigid shape in the world at ``center`` (m), moving at ``velocity`` (m/s).

    Parameters
    ----------
    center : world position of the shape's reference point (m).
    velocity : its world velocity (m/s), fed forward to the avoidance rows.
    name : what messages call it (default: the kind); names are unique in an avoidance
        set, which numbers repeated ones.
    """

    kind: ClassVar[str]
    label: ClassVar[str]
    color: ClassVar[tuple[int, int, int]] = (205, 150, 95)

    def __init__(self, center, velocity=(0.0, 0.0, 0.0), name: str | None = None) -> None:
        self.center = as_vector(center, 3, "center", MAX_POSITION_M)
        self.velocity = as_vector(velocity, 3, f"{self.kind} velocity", MAX_SPEED_M_S)
        if name is not None and (not isinstance(name, str) or not name.strip()):
            raise ValueError(f"an obstacle's name must be a non-empty string, got {short_repr(name)}")
        self.name = name or self.kind

    @abstractmethod
    def shape(self) -> coal.CollisionGeometry:
        """The coal shape in the obstacle's own frame (:meth:`pose`)."""

    def rotation(self) -> np.ndarray:
        """The world rotation of the shape's own axes (identity unless the kind turns)."""
        return np.eye(3)

    def pose(self) -> pin.SE3:
        """The world placement of the shape's own frame."""
        return pin.SE3(self.rotation(), self.center.copy())

    def primitive(self) -> tuple[int, np.ndarray, np.ndarray]:
        """``(kind code, dimensions, rotation)`` of the shape for the compiled step
        (:func:`~constraints.collision.primitives.primitive`); the step reads
        :attr:`center` and :attr:`velocity` before every step, copying them when
        :meth:`move_to` has replaced them."""
        kind, dimensions = primitive(self.shape())
        return kind, dimensions, self.rotation()

    @abstractmethod
    def dimensions(self) -> dict[str, object]:
        """The shape's dimensions, for drawing (m)."""

    @property
    def position(self) -> np.ndarray:
        """The world reference point (m), a copy: move it with :meth:`move_to`."""
        return self.center.copy()

    def move_to(self, position, velocity=(0.0, 0.0, 0.0)) -> None:
        """Move the reference point (m) and set the velocity fed forward (m/s): new
        :attr:`center` and :attr:`velocity` arrays (the compiled step sees a replaced
        array, not one changed in place)."""
        position = as_vector(position, 3, "center", MAX_POSITION_M)
        self.velocity = as_vector(velocity, 3, f"{self.kind} velocity", MAX_SPEED_M_S)
        self.center = position

    def geometry(self) -> ObstacleGeometry:
        """Everything a view draws, in the world frame."""
        return ObstacleGeometry(self.kind, self.name, self.kind, self.center.copy(),
                                self.rotation(), self.dimensions(), self.velocity.copy(),
                                self.color, self.label)

    # -- description: to and from a JSON-ready dict ----------------------------------------

    def to_dict(self) -> dict:
        """``kind`` and the constructor's arguments, JSON-ready (world frame, m, m/s);
        ``velocity`` left out at rest and ``name`` while it is the kind's."""
        data: dict = {"kind": self.kind}
        for name in inspect.signature(type(self)).parameters:
            value = getattr(self, name)
            if (name == "velocity" and not np.any(value)) or (name == "name" and value == self.kind):
                continue
            data[name] = value.tolist() if isinstance(value, np.ndarray) else value
        return data

    @staticmethod
    def from_dict(data: Mapping) -> "Obstacle":
        """Build an obstacle from :meth:`to_dict` output (``kind`` picks the type); bad
        input raises ``ValueError`` naming the field."""
        if not isinstance(data, Mapping):
            raise ValueError(f"an obstacle must be an object with a 'kind', got {short_repr(data)}")
        kind = data.get("kind")
        if not isinstance(kind, str) or kind not in OBSTACLE_TYPES:
            raise ValueError(f"unknown obstacle kind {short_repr(kind)}: {', '.join(OBSTACLE_TYPES)}")
        kind_type = OBSTACLE_TYPES[kind]
        fields = inspect.signature(kind_type).parameters
        given = {name: value for name, value in data.items() if name != "kind"}
        unknown = sorted(set(given) - set(fields))
        if unknown:
            raise ValueError(f"unknown field {unknown[0]!r} for a {kind} obstacle "
                             f"(its fields: {', '.join(fields)})")
        missing = [name for name, field in fields.items()
                   if field.default is inspect.Parameter.empty and name not in given]
        if missing:
            raise ValueError(f"a {kind} obstacle needs the field {missing[0]!r}")
        try:
            return kind_type(**given)
        except (ValueError, TypeError) as error:
            raise ValueError(f"bad {kind} obstacle: {error}") from error

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.to_dict()})"


def register_obstacle(obstacle_type: type[Obstacle]) -> type[Obstacle]:
    """Add ``obstacle_type`` to :data:`OBSTACLE_TYPES` under its ``kind``; returns it."""
    OBSTACLE_TYPES[obstacle_type.kind] = obstacle_type
    return obstacle_type


@register_obstacle
class Sphere(Obstacle):
    """A ball of ``radius`` (m) about ``center``."""

    kind = "sphere"
    label = "sphere"

    def __init__(self, center, radius: float, velocity=(0.0, 0.0, 0.0),
                 name: str | None = None) -> None:
        super().__init__(center, velocity, name)
        self.radius = as_number(radius, "radius", positive=True, maximum=MAX_OBSTACLE_SIZE_M)

    def shape(self) -> coal.CollisionGeometry:
        return coal.Sphere(self.radius)

    def dimensions(self) -> dict[str, object]:
        return {"radius": self.radius}


@register_obstacle
class Box(Obstacle):
    """A box of edges ``size`` (m, along its own x, y, z) about ``center``, turned by the
    roll-pitch-yaw angles ``rpy`` (rad, URDF's convention)."""

    kind = "box"
    label = "box"

    def __init__(self, center, size, rpy=(0.0, 0.0, 0.0), velocity=(0.0, 0.0, 0.0),
                 name: str | None = None) -> None:
        super().__init__(center, velocity, name)
        self.size = as_vector(size, 3, "size", MAX_OBSTACLE_SIZE_M)
        if not np.all(self.size > 0.0):
            raise ValueError(f"size must be three edges > 0 m, got {self.size.tolist()}")
        self.rpy = as_vector(rpy, 3, "rpy")

    def shape(self) -> coal.CollisionGeometry:
        return coal.Box(*self.size)

    def rotation(self) -> np.ndarray:
        return pin.rpy.rpyToMatrix(*self.rpy)

    def dimensions(self) -> dict[str, object]:
        return {"edges": self.size.tolist()}


@register_obstacle
class Capsule(Obstacle):
    """A capsule about ``center``: the points within ``radius`` (m) of the segment of
    ``length`` (m) along the unit world ``axis`` through ``center``."""

    kind = "capsule"
    label = "capsule"

    def __init__(self, center, radius: float, length: float, axis=(0.0, 0.0, 1.0),
                 velocity=(0.0, 0.0, 0.0), name: str | None = None) -> None:
        super().__init__(center, velocity, name)
        self.radius = as_number(radius, "radius", positive=True, maximum=MAX_OBSTACLE_SIZE_M)
        self.length = as_number(length, "length", 0.0, maximum=MAX_OBSTACLE_SIZE_M)
        self.axis = as_unit_vector(axis, "axis")

    def shape(self) -> coal.CollisionGeometry:
        return coal.Capsule(self.radius, self.length)

    def rotation(self) -> np.ndarray:
        return rotation_to(self.axis)

    def dimensions(self) -> dict[str, object]:
        return {"radius": self.radius, "length": self.length}


@register_obstacle
class HalfSpace(Obstacle):
    """Everything behind the plane through ``center`` with unit world ``normal``: the
    links stay on the side the normal points to (a table top, a wall)."""

    kind = "halfspace"
    label = "half-space"

    def __init__(self, center, normal, velocity=(0.0, 0.0, 0.0), name: str | None = None) -> None:
        super().__init__(center, velocity, name)
        self.normal = as_unit_vector(normal, "normal")

    def shape(self) -> coal.CollisionGeometry:
        return coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.0)  # solid: local z <= 0

    def rotation(self) -> np.ndarray:
        return rotation_to(self.normal)

    def dimensions(self) -> dict[str, object]:
        return {}
