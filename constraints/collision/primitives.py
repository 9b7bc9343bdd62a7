"""The pairs described as primitives, for the compiled CJM step (docs/design.md 18.4).

The compiled step measures the collision rows itself when every body is a sphere, a capsule
or a box and every obstacle one of those or a half-space: :func:`primitive` gives a coal
shape's kind and dimensions (None for any other shape, a mesh's convex hull), and
:class:`CollisionPrimitives` is what :meth:`CollisionAvoidance.primitives` hands over:
plain arrays, with the obstacles themselves, whose centres and velocities the step reads
before every step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import coal
import numpy as np

#: the primitive kinds by code (the C++ ``cjm::Shape::Kind``'s order)
PRIMITIVE_KINDS = ("sphere", "capsule", "box", "halfspace")
#: the code of a shape the compiled step does not cover
UNCOVERED = -1


def primitive(shape: coal.CollisionGeometry) -> tuple[int, np.ndarray]:
    """``(kind code, dimensions)`` of a coal shape: a sphere ``(radius, 0, 0)``, a capsule
    ``(radius, half length, 0)``, a box its half sides, a half-space (its solid side its
    frame's ``z <= 0``) zeros; ``(UNCOVERED, zeros)`` for any other shape."""
    if isinstance(shape, coal.Sphere):
        return PRIMITIVE_KINDS.index("sphere"), np.array([shape.radius, 0.0, 0.0])
    if isinstance(shape, coal.Capsule):
        return PRIMITIVE_KINDS.index("capsule"), np.array([shape.radius, shape.halfLength, 0.0])
    if isinstance(shape, coal.Box):
        return PRIMITIVE_KINDS.index("box"), np.asarray(shape.halfSide, dtype=float).copy()
    if isinstance(shape, coal.Halfspace) and np.allclose(shape.n, [0.0, 0.0, 1.0]) and shape.d == 0.0:
        return PRIMITIVE_KINDS.index("halfspace"), np.zeros(3)
    return UNCOVERED, np.zeros(3)


@dataclass(frozen=True)
class CollisionPrimitives:
    """The pairs of a :class:`CollisionAvoidance` as primitives.

    Attributes
    ----------
    body_names : (b,) each robot body's geometry name.
    body_joints : (b,) each body's joint; ``body_placements`` (b, 4, 4) its placement there.
    body_kinds, body_dimensions : (b,), (b, 3): :func:`primitive` of each body.
    obstacles : the :class:`~constraints.collision.obstacles.Obstacle` objects (their
        ``center`` and ``velocity`` read before each step).
    obstacle_kinds, obstacle_dimensions, obstacle_rotations : (o,), (o, 3), (o, 3, 3).
    pairs : (m, 2) indices into the bodies then the obstacles; ``pair_names`` (m,)
        ``"first | second"``.
    safety_distance, detection_distance, gain : ``d_s``, ``d_i`` (m) and
        ``xi / (d_i - d_s)`` (1/s).
    """

    body_names: tuple[str, ...]
    body_joints: np.ndarray
    body_placements: np.ndarray
    body_kinds: np.ndarray
    body_dimensions: np.ndarray
    obstacles: tuple[Any, ...]
    obstacle_kinds: np.ndarray
    obstacle_dimensions: np.ndarray
    obstacle_rotations: np.ndarray
    pairs: np.ndarray
    pair_names: tuple[str, ...]
    safety_distance: float
    detection_distance: float
    gain: float

    @property
    def uncovered(self) -> tuple[str, ...]:
        """The names of the bodies and obstacles that are not primitives (empty: the
        compiled step measures every pair)."""
        return (*(name for name, kind in zip(self.body_names, self.body_kinds.tolist())
                  if kind == UNCOVERED),
                *(obstacle.name for obstacle, kind in zip(self.obstacles, self.obstacle_kinds.tolist())
                  if kind == UNCOVERED))
