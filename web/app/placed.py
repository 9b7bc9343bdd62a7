"""What the operator places in the scene and moves by a gizmo (issue 34, the placed-item
type): a constraint's geometry (docs/design.md section 5.5) or an obstacle (section 18).
Either glides to where the operator put it, its velocity fed forward
(:mod:`teleop.loop.moving_geometry`); the kind of item is its subclass's field."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import ClassVar, Protocol, TypeVar

import numpy as np

from teleop.loop.moving_geometry import MovingGeometry


class Placeable(MovingGeometry, Protocol):
    """What a placed item is to its entry: a kind and a world reference point, moved by
    the tick (:mod:`teleop.loop.moving_geometry`)."""

    @property
    def kind(self) -> str: ...


Entry = TypeVar("Entry", bound="PlacedEntry")


@dataclass
class PlacedEntry:
    """An item placed by the operator: its ``id``, where the operator put it (``goal``,
    world, m) and whether it is there and at rest (``settled``: the tick leaves it
    alone). The item itself is the subclass's field, :attr:`moved`."""

    #: whether a session recording replays the item's moves (a constraint's, not an
    #: obstacle's: a session file records the constraints' edits)
    recorded: ClassVar[bool] = False

    id: str
    goal: np.ndarray  # where the operator put it (the control loop moves it there)
    settled: bool = True

    @property
    def moved(self) -> Placeable:
        """What the gizmo moves (:mod:`teleop.loop.moving_geometry`)."""
        raise NotImplementedError

    @property
    def kind(self) -> str:
        """The item's ``kind`` name."""
        return self.moved.kind

    @property
    def position(self) -> np.ndarray:
        """Where the item is now (world reference point, a copy)."""
        return self.moved.position

    def restored(self: Entry) -> Entry:
        """This entry settled if its item is at its goal (read from a scene file)."""
        self.settled = bool(np.array_equal(self.goal, self.position))
        return self


def remove_every(ids: Iterable[str], remove: Callable[[str], object]) -> int:
    """``remove`` each of ``ids`` (listed first: ``remove`` may change where they come
    from); how many there were."""
    listed = list(ids)
    for entry_id in listed:
        remove(entry_id)
    return len(listed)
