"""The task stage's objective, normalised by the task's scale (docs/design.md 10.1)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..numerics import INFINITE_BOUND


class TaskObjective(NamedTuple):
    """``M``, its target ``m``, the Hessian ``M^T M`` and the gradient ``-M^T m``."""

    stacked: np.ndarray
    stacked_target: np.ndarray
    hessian: np.ndarray
    gradient: np.ndarray


class TaskAssembly:
    """``M = [A; W^1/2 J_e / sqrt(s); D / sqrt(s)]`` and ``m = [b; W^1/2 V / sqrt(s); 0]``.

    ``s = |W^1/2 J_e|_F^2 / rows`` is the mean squared singular value of the weighted task
    Jacobian. The objective ``1/2 (|J_e qd - V|_W^2 + |D qd|^2) / s + 1/2 |A qd - b|^2``
    (the last term zero on the feasible set) then has Hessian ``M^T M``, of order one
    whatever the robot's size, and gradient ``-M^T m``. The buffers of ``M`` and ``m``
    are kept while their shape does not change.
    """

    def __init__(self, nv: int) -> None:
        self._stacked, self._stacked_target = np.empty((0, nv)), np.empty(0)

    def assemble(self, weighted_jacobian: np.ndarray, weighted_twist: np.ndarray,
                 A: np.ndarray | None, b: np.ndarray | None,
                 damping_rows: np.ndarray) -> TaskObjective:
        """The objective for ``W^1/2 J_e``, ``W^1/2 V``, the rows ``A qd = b`` (None:
        none) and the damping rows ``D``."""
        m, nv = weighted_jacobian.shape
        k = 0 if A is None else A.shape[0]
        d = damping_rows.shape[0]
        if self._stacked.shape[0] != k + m + d:
            self._stacked, self._stacked_target = np.empty((k + m + d, nv)), np.empty(k + m + d)
        stacked, stacked_target = self._stacked, self._stacked_target
        square_sum = float(np.vdot(weighted_jacobian, weighted_jacobian))
        inverse_root_scale = math.sqrt(m / square_sum) if square_sum > 0.0 else 1.0
        np.multiply(weighted_jacobian, inverse_root_scale, out=stacked[k:k + m])
        np.multiply(weighted_twist, inverse_root_scale, out=stacked_target[k:k + m])
        if k:
            stacked[:k] = A
            stacked_target[:k] = b
        if d:
            np.multiply(damping_rows, inverse_root_scale, out=stacked[k + m:])
            stacked_target[k + m:] = 0.0
        hessian = np.dot(stacked.T, stacked)
        gradient = np.dot(stacked_target, stacked)
        np.negative(gradient, out=gradient)
        return TaskObjective(stacked, stacked_target, hessian, gradient)


def bounded_box(lower: np.ndarray, upper: np.ndarray
                ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The joint box with ``+-INFINITE_BOUND`` for no bound; ``(None, None)`` if nothing
    is bounded."""
    if not math.isfinite(sum(lower.tolist()) + sum(upper.tolist())):
        if not (np.isfinite(lower).any() or np.isfinite(upper).any()):
            return None, None  # nothing bounded
        lower = np.where(np.isfinite(lower), lower, -INFINITE_BOUND)
        upper = np.where(np.isfinite(upper), upper, INFINITE_BOUND)
    return lower, upper
