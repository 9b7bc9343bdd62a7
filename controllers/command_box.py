"""The joint box of each step and the commands it counts from (docs/design.md 8.2-8.5)."""

from __future__ import annotations

import numpy as np

from .joint_limits import JointBounds


class CommandBox:
    """Where the next command may be: :class:`JointBounds` at ``q``, around the commands sent.

    Without acceleration limits the box is the velocity and braking-aware position limits
    (docs/design.md 8.2-8.3). With them it is also the window ``|qd - qd_prev| <= a dt``
    around the previous command (8.4), and with jerk limits the window
    ``|(qd - qd_prev) - (qd_prev - qd_prev2)| <= j dt^2`` around the previous change (8.5).
    This object keeps those two references: :meth:`remember` each command sent,
    :meth:`reset` to start from rest.

    ``previous_command`` and ``previous_change`` are the arrays the box reads; a controller
    whose step keeps them itself (the CJM's backends) points them at its step's arrays.
    """

    def __init__(self, joint_bounds: JointBounds, nv: int) -> None:
        self.joint_bounds = joint_bounds
        #: the previous command, the acceleration window's centre (zero at rest)
        self.previous_command = np.zeros(nv)
        #: the previous command minus the one before, the jerk window's centre
        self.previous_change = np.zeros(nv)

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
