"""A period run now and measured later (docs/design.md 5.1, section 7).

The measures of section 7 steer nothing: the supervisor's (docs/design.md 5.2), which scale
the operator's motion, are taken in the hot path at the sensed configuration; the rest
(the command's residual and velocities, the end-of-period errors) are only reported. A run
that reads them only once it is over (``teleop compare``) keeps, every period, what they
are computed from, and takes them after the run
(:meth:`~teleop.loop.TeleopLoop.measure_later`), with the same code and the same numbers
as :meth:`~teleop.loop.TeleopLoop.tick`; the period itself costs the hot path and the
copies below.

What a period keeps: its :class:`~teleop.loop.records.PendingStep`, the true
configuration and time at its end, the plant's measures of the period, and the geometry
at the two instants the measures read it (:class:`Geometry`: the command's, then the end
of the period's, after the geometry has moved on).
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from constraints import Constraint

from .records import PendingStep, StepRecord


def geometry_copy(constraint: Constraint) -> Constraint:
    """``constraint`` as it is now, kept when it moves on: a shallow copy (its attributes'
    values shared). A constraint's arrays are never written in place (its geometry moves
    by ``move_to`` and its setters, which assign new ones), so the copy keeps the geometry
    and gain of this instant; ``copy.copy`` costs 50 times more, through the pickling
    protocol."""
    kept = object.__new__(type(constraint))
    kept.__dict__.update(constraint.__dict__)
    return kept


class Geometry(NamedTuple):
    """The constraints at one instant: their copies (:func:`geometry_copy`), the frame each
    is on, their names and their rows' labels (``teleop.loop.naming``). A named tuple: one
    is built every period, in the hot path, at a third of a frozen dataclass's cost."""

    constraints: tuple[Constraint, ...]
    frames: Sequence[int]
    names: tuple[str, ...]
    labels: tuple[str, ...]


class MeasuredLater(NamedTuple):
    """One period run and not yet measured: the step (its status and message are already
    the loop's), the geometry at its command and at its end, the true configuration and
    the time at its end, and the plant's measures of the period (None without a plant);
    ``record``: its measures when they were taken at once (None: not yet). A named tuple,
    as :class:`Geometry`."""

    step: PendingStep
    command: Geometry
    end: Geometry
    q: np.ndarray
    t: float
    plant: object | None
    record: StepRecord | None = None

    @property
    def failed(self) -> bool:
        """Whether the loop's status is ``failed`` (:attr:`StepRecord.failed`)."""
        return self.step.status == "failed"

    @property
    def message(self) -> str:
        """The loop's message in words (:attr:`StepRecord.message`)."""
        return self.step.message
