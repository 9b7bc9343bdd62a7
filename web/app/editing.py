"""Editing the constraints: placing one (any registered kind, from its declaration, or a
built one), moving its geometry, removing it (docs/design.md section 5.5); the placed
ones are what every loop holds (:class:`.robots.Robots` reads them)."""

from __future__ import annotations

import itertools
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from constraints import CONSTRAINT_TYPES, Constraint
from constraints.kinematics import frame_placement
from constraints.registry import constraint_type
from constraints.validation import as_vector, short_repr
from teleop.robots import Robot

from ..constraint_placement import place
from .limits import MAX_TARGET_DISTANCE
from .placed import PlacedEntry, remove_every
from .placing import Placement, moving_links
from .plant import apply_wall
from .recording import SessionRecording


@dataclass
class ConstraintEntry(PlacedEntry):
    """A constraint placed by the operator, with the geometry its gizmo drives."""

    recorded: ClassVar[bool] = True

    constraint: Constraint = field(kw_only=True)

    @property
    def moved(self) -> Constraint:
        """What the gizmo moves (:mod:`teleop.loop.moving_geometry`)."""
        return self.constraint


@dataclass(frozen=True)
class EditingSession:
    """What :class:`ConstraintEditing` reads of the rest of the session (under its lock)."""

    #: the main robot's configuration now (a constraint is placed where the robot is)
    configuration: Callable[[], np.ndarray]
    #: the constraints' gain now (1/s; a new constraint takes it)
    gain: Callable[[], float]
    #: every loop takes the placed constraints (``ValueError`` when a controller
    #: refuses them, and then nothing changed)
    changed: Callable[[], None]


class ConstraintEditing:
    """The constraints the operator placed (``app.constraints``), a component of
    :class:`web.app.TeleopApp` that owns them: :attr:`entries` by id and the counter of new
    ids. Its actions take the session's lock; the control tick reads :attr:`entries`
    holding it.

    Parameters
    ----------
    robot : the session's robot.
    lock : the session's lock.
    wall_stiffness : the abdominal wall's stiffness (N/m) at every port, or None: each
        port's own (:func:`.plant.apply_wall`).
    recorder : the session's recording (it gets every change).
    session : what it reads of the rest of the session (:class:`EditingSession`).
    """

    def __init__(self, robot: Robot, lock: threading.RLock, wall_stiffness: float | None,
                 recorder: SessionRecording, session: EditingSession) -> None:
        self.robot = robot
        self._lock = lock
        self._wall_stiffness = wall_stiffness
        self._recorder = recorder
        self._session = session
        self.entries: dict[str, ConstraintEntry] = {}
        self._ids = itertools.count(1)
        self._data = robot.model.createData()  # for the placements, under the lock

    def placed(self) -> list[Constraint]:
        """The placed constraints (caller holds the lock)."""
        return [entry.constraint for entry in self.entries.values()]

    @property
    def moving_links(self) -> tuple[str, ...]:
        """The links a constraint on "any moving link" may hold: the constrained links
        (one per arm) first, then every other link that moves (a mobile base...)."""
        return moving_links(self.robot)

    def add(self, constraint: str | Constraint, **fields) -> str:
        """Place a constraint; its id (``"<kind>-<n>"``).

        ``constraint`` is a kind name of :data:`constraints.CONSTRAINT_TYPES` with the
        values of that type's placement fields (:mod:`web.constraint_placement`:
        ``add(kind, distance=0.08)``; a field left out takes its declared default, a link
        its first choice): the constraint goes where the main robot is now. Or it is a
        built constraint, placed as it is. Either takes the session's drift gain. A bad
        value, or a constraint the controllers refuse (unknown link, gain unstable at this
        rate), raises ``ValueError`` and places nothing.
        """
        if isinstance(constraint, str):
            kind_type = constraint_type(constraint)
            with self._lock:
                q = self._session.configuration()
                values = Placement(kind_type, self.robot, lambda link: frame_placement(
                    self.robot.model, q, link, self._data)).values(fields)
                return self._place(place(kind_type, self.robot, q, **values))
        if not isinstance(constraint, Constraint):
            raise ValueError(f"expected a constraint or a constraint kind "
                             f"({', '.join(CONSTRAINT_TYPES)}), got {short_repr(constraint)}")
        if fields:
            raise ValueError(f"a built constraint is placed as it is: no fields, got "
                             f"{sorted(fields)}")
        return self._place(constraint)

    def _place(self, constraint: Constraint) -> str:
        """Add ``constraint`` at its position with the session's gain; its new id."""
        with self._lock:
            constraint.gain = self._session.gain()
            apply_wall(constraint, self._wall_stiffness)
            entry_id = f"{constraint.kind}-{next(self._ids)}"
            if entry_id in self.entries:
                raise ValueError(f"a constraint {entry_id!r} is already placed")
            self.entries[entry_id] = ConstraintEntry(entry_id, constraint.position,
                                                     constraint=constraint)
            try:
                self._session.changed()
            except ValueError:
                del self.entries[entry_id]
                self._session.changed()
                raise
            self._recorder.add(entry_id, constraint)
            return entry_id

    def move(self, entry_id: str, position) -> None:
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

    def remove(self, entry_id: str) -> None:
        """Remove the constraint ``entry_id``."""
        with self._lock:
            if self.entries.pop(entry_id, None) is None:
                raise ValueError(f"no constraint {entry_id!r}")
            self._session.changed()
            self._recorder.remove(entry_id)

    def clear(self) -> int:
        """Remove every constraint; how many there were."""
        with self._lock:
            return remove_every(self.entries, self.remove)

    def restore(self, entries: dict[str, ConstraintEntry]) -> None:
        """A scene's constraints (caller holds the lock; the loops already hold them); the
        next ids follow theirs."""
        self.entries = entries
        numbers = [int(entry_id.rsplit("-", 1)[1]) for entry_id in entries
                   if entry_id.rsplit("-", 1)[-1].isdigit()]
        self._ids = itertools.count(max(numbers, default=0) + 1)
