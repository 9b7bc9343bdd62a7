"""The tissue a physics plant puts where a constraint is (docs/design.md section 17.2).

A constraint type whose geometry stands for tissue the instrument passes through (a hole:
the abdominal wall at a port) has a :class:`Wall` registered here under its type
(:func:`register_wall`); the plant, the supervisor and the reports look it up by type
(:func:`wall_of`, a subclass inheriting its base's), so the constraint itself carries only
its math and the wall's parameters among its fields.
"""

from __future__ import annotations

from typing import Any, Protocol, TypeVar

import numpy as np

from constraints import Constraint, Hole

#: the constraint type a wall is registered for
C = TypeVar("C", bound=Constraint, contravariant=True)


class Wall(Protocol[C]):
    """What the plant asks of the tissue at one constraint (world frame, SI units)."""

    def port(self, constraint: C, rotation: np.ndarray,
             translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the instrument crosses the tissue, for the constraint's link frame at
        ``(rotation, translation)``: the point (3,) and the instrument's world axis (3,)."""
        ...

    def force(self, constraint: C, point: np.ndarray, axis: np.ndarray,
              point_velocity: np.ndarray) -> np.ndarray:
        """The tissue's world force (N) on the instrument at ``point`` (:meth:`port`),
        the instrument's material point there moving at ``point_velocity`` (m/s)."""
        ...

    def spring(self, constraint: C, point: np.ndarray) -> np.ndarray:
        """The elastic part of :meth:`force` (N): the tissue's pull back to rest."""
        ...

    def displacement(self, constraint: C, point: np.ndarray) -> float:
        """How far (m) the tissue is pushed from rest at ``point``."""
        ...

    def set_stiffness(self, constraint: C, stiffness: float) -> None:
        """Give the tissue at ``constraint`` the lateral ``stiffness`` (N/m)."""
        ...

    def compiled_parameters(self, constraint: C) -> np.ndarray | None:
        """The 11 numbers ``port_wall.c`` applies the wall from inside MuJoCo's step
        (:mod:`teleop.plants.compiled_wall`): the link axis (link frame), the centre and its
        velocity (world), the lateral stiffness (N/m) and damping (N s/m); None for a wall
        with no compiled form (the plant then applies it from Python)."""
        ...

    def compiled_version(self, constraint: C) -> tuple[object, ...]:
        """Objects that stay the same (``is``) as long as :meth:`compiled_parameters` gives
        the same numbers: the plant reads the parameters again when one is replaced."""
        ...


class PortWall:
    """The abdominal wall around a hole's port, a lateral spring-damper (docs/design.md
    17.2): the hole's ``tissue_stiffness`` ``k`` and ``tissue_damping`` ``c_d``."""

    def port(self, hole: Hole, rotation: np.ndarray,
             translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The point of the link axis nearest the centre, ``P = o + ((c - o) . a) a``, and
        the world axis ``a = R a_link``."""
        axis = rotation @ hole.link_axis
        return translation + float(axis @ (hole.center - translation)) * axis, axis

    def force(self, hole: Hole, point: np.ndarray, axis: np.ndarray,
              point_velocity: np.ndarray) -> np.ndarray:
        """``F = -k (P - c) - c_d (v - v_c)_perp``: ``P - c`` the lateral offset of the link
        axis from the centre, ``v`` the instrument's velocity at ``P``, ``v_c`` the
        centre's, ``perp`` across the axis. A spring-damper, not a rigid constraint: the
        controller's error shows."""
        relative = point_velocity - hole.velocity
        lateral_velocity = relative - float(axis @ relative) * axis
        return self.spring(hole, point) - hole.tissue_damping * lateral_velocity

    def spring(self, hole: Hole, point: np.ndarray) -> np.ndarray:
        """``-k (P - c)``."""
        return -hole.tissue_stiffness * (point - hole.center)

    def displacement(self, hole: Hole, point: np.ndarray) -> float:
        """``|P - c|``."""
        return float(np.linalg.norm(point - hole.center))

    def set_stiffness(self, hole: Hole, stiffness: float) -> None:
        """The hole's ``tissue_stiffness``."""
        hole.tissue_stiffness = stiffness

    def compiled_parameters(self, hole: Hole) -> np.ndarray:
        """``a_link``, ``c``, ``v_c``, ``k``, ``c_d``: the math above, in ``port_wall.c``."""
        return np.concatenate([hole.link_axis, hole.center, hole.velocity,
                               [hole.tissue_stiffness, hole.tissue_damping]])

    def compiled_version(self, hole: Hole) -> tuple[object, ...]:
        """The hole's ``revision``: replaced whenever one of its fields (the axis, the
        centre, its velocity, ``k``, ``c_d``...) is assigned, :mod:`constraints.revision`."""
        return (hole.revision,)


#: constraint type -> its wall; a type not here (nor any of its bases) has none
WALLS: dict[type[Constraint], Wall[Any]] = {}
#: every constraint type :func:`wall_of` was asked about -> its wall (or None), emptied
#: whenever a wall is registered
_WALL_OF_TYPE: dict[type, Wall[Any] | None] = {}


def register_wall(constraint_type: type[C], wall: Wall[C]) -> None:
    """Put ``wall`` wherever a constraint of ``constraint_type`` (or of a subclass without
    its own) is, on a physics plant."""
    WALLS[constraint_type] = wall
    _WALL_OF_TYPE.clear()


def wall_of(constraint: Constraint) -> Wall[Any] | None:
    """The wall a physics plant puts at ``constraint``, or None (the type's nearest
    registered base decides; looked up once a type, a plant asks every period)."""
    kind = type(constraint)
    try:
        return _WALL_OF_TYPE[kind]
    except KeyError:
        wall = next((WALLS[base] for base in kind.__mro__ if base in WALLS), None)
        _WALL_OF_TYPE[kind] = wall
        return wall


def has_wall(constraint: Constraint) -> bool:
    """Whether a physics plant puts a wall at ``constraint``."""
    return wall_of(constraint) is not None


register_wall(Hole, PortWall())
