"""The joint box of each step and the commands it counts from (docs/design.md 8.2-8.5)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from .joint_limits import JointBounds


class HoldsCommands(Protocol):
    """Where the commands sent are kept: ``previous`` (the previous command) and
    ``previous_change`` (it minus the one before), (nv,) arrays written in place."""

    previous: np.ndarray
    previous_change: np.ndarray


@dataclass
class CommandHistory:
    """The commands sent, kept by the box itself (the QP's and mink's)."""

    previous: np.ndarray
    previous_change: np.ndarray


class CommandBox:
    """Where the next command may be: :class:`JointBounds` at ``q``, around the commands sent.

    Without acceleration limits the box is the velocity and braking-aware position limits
    (docs/design.md 8.2-8.3). With them it is also the window ``|qd - qd_prev| <= a dt``
    around the previous command (8.4), and with jerk limits the window
    ``|(qd - qd_prev) - (qd_prev - qd_prev2)| <= j dt^2`` around the previous change (8.5).
    :meth:`remember` each command sent; :meth:`reset` to start from rest.

    The two references are read from :attr:`history` at every use: a controller whose step
    keeps them itself (the CJM's backends, whose compiled step moves them when it grows)
    hands its step over as the history.
    """

    def __init__(self, joint_bounds: JointBounds, nv: int) -> None:
        self.joint_bounds = joint_bounds
        #: the commands sent (:class:`HoldsCommands`); zero at rest
        self.history: HoldsCommands = CommandHistory(np.zeros(nv), np.zeros(nv))

    @property
    def previous_command(self) -> np.ndarray:
        """The previous command, the acceleration window's centre (the history's array)."""
        return self.history.previous

    @property
    def previous_change(self) -> np.ndarray:
        """The previous command minus the one before, the jerk window's centre."""
        return self.history.previous_change

    @property
    def jerk_reference(self) -> np.ndarray | None:
        """:attr:`previous_change` when there are jerk limits, else None."""
        return None if self.joint_bounds.jerk_step is None else self.previous_change

    def box(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The box ``lower <= qd <= upper`` of the next step at ``q``."""
        return self.joint_bounds.box(q, self.previous_command, self.jerk_reference)

    def stop_command(self, q: np.ndarray) -> np.ndarray:
        """The command nearest zero inside the box: zero, unless a joint past its position
        limit must come back (its box excludes zero) or the acceleration limits cannot
        stop at once (a controlled stop)."""
        lower, upper = self.box(q)
        return np.clip(0.0, lower, upper)

    def remember(self, command: np.ndarray) -> None:
        """``command`` sent: the reference of the next step's acceleration and jerk box."""
        if self.joint_bounds.jerk_step is not None:  # the jerk window's centre, only there
            np.subtract(command, self.previous_command, out=self.previous_change)
        self.previous_command[:] = command

    def reset(self) -> None:
        """Forget the commands sent: the next step starts from rest."""
        self.previous_command[:] = 0.0
        self.previous_change[:] = 0.0
