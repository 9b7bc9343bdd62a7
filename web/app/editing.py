"""Editing the constraints: placing one (any registered kind, from its declaration, or a
built one), moving its geometry, removing it (docs/design.md section 5.5)."""

from __future__ import annotations

import itertools
import math
import threading
from dataclasses import dataclass, field

import pinocchio as pin

from constraints import CONSTRAINT_TYPES, Constraint
from constraints.kinematics import frame_placement
from constraints.registry import constraint_type
from constraints.validation import as_vector, short_repr
from teleop.robots import Robot

from .robots import Robots
from .limits import MAX_TARGET_DISTANCE
from .placed import PlacedEntry
from .placing import Placement, moving_links
from .plant import PlantChoice, apply_wall


@dataclass
class ConstraintEntry(PlacedEntry):
    """A constraint placed by the operator, with the geometry its gizmo drives."""

    constraint: Constraint = field(kw_only=True)

    @property
    def moved(self) -> Constraint:
        """What the gizmo moves (:mod:`teleop.loop.moving_geometry`)."""
        return self.constraint


class Editing:
    """The constraint editing of :class:`web.app.TeleopApp` (its state: ``entries`` by id
    and the counter of new ids)."""

    robots: Robots
    robot: Robot
    plant: PlantChoice
    entries: dict[str, ConstraintEntry]
    _ids: itertools.count
    _lock: threading.RLock
    _view_data: pin.Data

    def _placed(self) -> list[Constraint]:
        """The placed constraints (caller holds the lock)."""
        return [entry.constraint for entry in self.entries.values()]

    def _link_placement(self, link: str, which: str = "main") -> pin.SE3:
        """World placement of ``link`` on robot ``which`` now (caller holds the lock)."""
        return frame_placement(self.robot.model, self.robots.loops[which].q, link, self._view_data)

    @property
    def moving_links(self) -> tuple[str, ...]:
        """The links a constraint on "any moving link" may hold: the constrained links
        (one per arm) first, then every other link that moves (a mobile base...)."""
        return moving_links(self.robot)

    def add_constraint(self, constraint: str | Constraint, **fields) -> str:
        """Place a constraint; its id (``"<kind>-<n>"``).

        ``constraint`` is a kind name of :data:`constraints.CONSTRAINT_TYPES` with the
        values of that type's ``placement`` fields (``add_constraint(kind, distance=0.08)``;
        a field left out takes its declared default, a link its first choice): the
        constraint goes where the main robot is now. Or it is a built constraint, placed
        as it is. Either takes the app's drift gain. A bad value, or a constraint the
        controllers refuse (unknown link, gain unstable at this rate), raises
        ``ValueError`` and places nothing.
        """
        if isinstance(constraint, str):
            kind_type = constraint_type(constraint)
            with self._lock:
                values = Placement(kind_type, self.robot, self._link_placement).values(fields)
                return self._place(kind_type.place(self.robot, self.robots.loops["main"].q, **values))
        if not isinstance(constraint, Constraint):
            raise ValueError(f"expected a constraint or a constraint kind "
                             f"({', '.join(CONSTRAINT_TYPES)}), got {short_repr(constraint)}")
        if fields:
            raise ValueError(f"a built constraint is placed as it is: no fields, got "
                             f"{sorted(fields)}")
        return self._place(constraint)

    def _place(self, constraint: Constraint) -> str:
        """Add ``constraint`` at its position with the app's gain; its new id."""
        with self._lock:
            constraint.gain = self.robots.gain
            apply_wall(constraint, self.plant.wall_stiffness)
            entry_id = f"{constraint.kind}-{next(self._ids)}"
            if entry_id in self.entries:
                raise ValueError(f"a constraint {entry_id!r} is already placed")
            self.entries[entry_id] = ConstraintEntry(entry_id, constraint.position,
                                                     constraint=constraint)
            try:
                self.robots.sync_constraints()
            except ValueError:
                del self.entries[entry_id]
                self.robots.sync_constraints()
                raise
            self.recorder.add(entry_id, constraint)
            return entry_id

    def move_constraint(self, entry_id: str, position) -> None:
        """Move a constraint's geometry (its world reference point): the robot follows it."""
        position = as_vector(position, 3, "constraint position")
        with self._lock:
            if entry_id not in self.entries:
                raise ValueError(f"no constraint {entry_id!r}")
            entry = self.entries[entry_id]
            distance = math.hypot(*(position - entry.position))
            if distance > MAX_TARGET_DISTANCE:
                raise ValueError(f"constraint position refused: {distance:.3g} m from where "
                                 f"{entry_id} is, more than {MAX_TARGET_DISTANCE:g} m")
            entry.goal = position.copy()
            entry.settled = False

    def remove_constraint(self, entry_id: str) -> None:
        with self._lock:
            if self.entries.pop(entry_id, None) is None:
                raise ValueError(f"no constraint {entry_id!r}")
            self.robots.sync_constraints()
            self.recorder.remove(entry_id)

    def clear_constraints(self) -> int:
        """Remove every constraint; how many there were."""
        with self._lock:
            ids = list(self.entries)
            for entry_id in ids:
                self.remove_constraint(entry_id)
            return len(ids)
