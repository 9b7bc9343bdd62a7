"""The plant protocol: what stands between the controller and the robot's true joints."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np
import pinocchio as pin

from constraints import Constraint


class Plant(Protocol):
    """What stands between the controller and the robot's true joints (docs/design.md
    sections 15.1, 17): the loop reads the configuration through :meth:`sense` and moves
    the robot with what :meth:`advance` returns. A plant whose encoders are noisy also
    says so in ``encoder_noise`` (rad, its std; the loop's state observer, docs/design.md
    5.6, takes 0 from a plant without it). :meth:`advance` and :meth:`close` came later:
    a plant without them still runs (:func:`advance_of`, :func:`close_plant`)."""

    def sense(self, q: np.ndarray) -> np.ndarray:
        """The configuration the loop measures when the robot's true one is ``q``."""

    def actuate(self, qd: np.ndarray, q: np.ndarray,
                constraints: Sequence[Constraint]) -> np.ndarray:
        """The mean joint velocity over the coming period, given this period's command,
        the true configuration ``q`` and the constraints in the scene."""

    def advance(self, qd: np.ndarray, q: np.ndarray, constraints: Sequence[Constraint],
                dt: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`actuate`'s velocity ``moved`` and the configuration it takes ``q`` to
        over ``dt``, ``pin.integrate(model, q, moved dt)`` to the last bit (the MuJoCo plant
        computes it in its compiled period, docs/design.md 17.5)."""

    def reset(self, q: np.ndarray | None = None) -> None:
        """Back to rest (at ``q``, when the plant keeps a configuration of its own)."""

    def measures(self) -> object | None:
        """What the plant measured over the last period (its own type), or None."""

    def close(self) -> None:
        """Let go of what the plant holds (a robot on the wire: zeros published, its node
        closed); nothing for a simulated robot. Called once, when the loop's run ends."""


#: A plant's :meth:`Plant.advance`: ``(qd, q, constraints, dt) -> (moved, q_next)``.
Advance = Callable[[np.ndarray, np.ndarray, Sequence[Constraint], float],
                   tuple[np.ndarray, np.ndarray]]


def advance_of(plant: Plant, model: pin.Model) -> Advance:
    """``plant``'s :meth:`Plant.advance`; for a plant written before it (sense, actuate,
    reset, measures), its :meth:`Plant.actuate` then ``pin.integrate`` on ``model``."""
    advance = getattr(plant, "advance", None)
    if advance is not None:
        return advance

    def actuate_then_integrate(qd: np.ndarray, q: np.ndarray,
                               constraints: Sequence[Constraint],
                               dt: float) -> tuple[np.ndarray, np.ndarray]:
        moved = plant.actuate(qd, q, constraints)
        return moved, pin.integrate(model, q, moved * dt)

    return actuate_then_integrate


def close_plant(plant: Plant) -> None:
    """:meth:`Plant.close`, when ``plant`` has one (a plant written before it holds
    nothing to let go)."""
    close = getattr(plant, "close", None)
    if close is not None:
        close()
