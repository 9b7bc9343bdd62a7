"""The collision rows measured inside the compiled step (docs/design.md section 18.4).

:class:`CompiledCollisions` hands a :class:`~constraints.collision.CollisionAvoidance`'s
pairs, as primitives (:meth:`CollisionAvoidance.primitives`), to the C++ pipeline, which
then measures them in ``prepare()`` right after the kinematics: the broadphase, the
signed distances and witness points, the damper rows into the step's pair buffer. Python
only checks, before each step, that the pairs have not been rebuilt since
(``CollisionAvoidance.revision``: obstacles added or removed, ports); the obstacles'
centres and velocities are read by the C++ side (a replaced array is copied). After the
step :meth:`CompiledCollisions.rows` reads the rows back (one C++ call copying them) as
the :class:`~constraints.collision.CollisionRows` the report carries.

A body or obstacle that is not a primitive (a mesh's convex hull) leaves the rows to
Python: :attr:`CompiledCollisions.fallback` says which.
"""

from __future__ import annotations

import numpy as np

from constraints.collision import CollisionAvoidance, CollisionRows
from constraints.collision.primitives import PRIMITIVE_KINDS

from ._step import SHAPE_KINDS, Pipeline

if tuple(sorted(SHAPE_KINDS, key=SHAPE_KINDS.get)) != PRIMITIVE_KINDS:
    raise ImportError("controllers.cjm._step numbers the shapes otherwise: rebuild it")


class CompiledCollisions:
    """``collisions``' rows measured by ``pipeline`` (described at the first step and
    again whenever ``collisions.revision`` changes)."""

    def __init__(self, pipeline: Pipeline, collisions: CollisionAvoidance) -> None:
        self.pipeline = pipeline
        self.collisions = collisions
        #: why Python measures the rows (the shapes it cannot), None when the C++ does
        self.fallback: str | None = None
        self._revision: int | None = None

    def stale(self) -> bool:
        """Whether the pairs were rebuilt since they were last described."""
        return self._revision != self.collisions.revision

    def pair_count(self) -> int:
        """The number of pairs the description holds (the pair buffer must take them)."""
        return len(self.collisions.pairs)

    def describe(self) -> None:
        """Hand the pairs to the pipeline, or record why Python measures them."""
        description = self.collisions.primitives()
        revision = self.collisions.revision
        uncovered = description.uncovered
        if uncovered:
            self.fallback = (f"the compiled step measures spheres, capsules, boxes and half-spaces "
                             f"only, not {', '.join(uncovered)}: Python measures the collision rows")
            self.pipeline.clear_collisions()
            self._revision = revision
            return
        self.fallback = None
        self.pipeline.set_collisions(
            description.body_joints.tolist(), list(description.body_placements),
            description.body_kinds.tolist(), list(description.body_dimensions),
            list(description.obstacles), description.obstacle_kinds.tolist(),
            list(description.obstacle_dimensions), list(description.obstacle_rotations),
            description.pairs.tolist(), list(description.pair_names), description.safety_distance,
            description.detection_distance, description.gain)
        self._revision = revision  # only once the pipeline took them

    def pair_indices(self) -> np.ndarray:
        """The index (into ``collisions.pairs``) of each row of the last step (a copy)."""
        row_pairs, _, _, summary = self.pipeline.collision_views()
        return row_pairs[:int(summary[0])].copy()

    def rows(self) -> CollisionRows:
        """The rows the last step measured (copies of the C++ buffers), kept as
        ``collisions.last_rows``."""
        self.collisions.last_rows = rows = CollisionRows(*self.pipeline.collision_report())
        return rows
