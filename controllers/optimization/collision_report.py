"""What an optimiser's step says about its collision rows (docs/design.md 18.5).

The rows are ``rows qd >= lower`` (:class:`constraints.collision.CollisionRows`); a row is
held at its bound when ``rows qd - lower`` is at most the solve's accuracy. The QP holds
them with the barriers; the mink peer reports what mink's own limit held.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from constraints.collision import CollisionRows

from ..base import SolveInfo, StepStatus

#: A collision row is at its bound when ``rows qd - lower`` is at most this (m/s), or the
#: backend's absolute tolerance if larger (OSQP's rows are only that accurate).
AT_BOUND = 1e-9


def rows_at_bound(rows: CollisionRows, qd: np.ndarray, tolerance: float = AT_BOUND) -> np.ndarray:
    """Indices of the rows ``qd`` holds at their bound (or breaks)."""
    if not rows.size:
        return np.zeros(0, dtype=int)
    return np.flatnonzero(rows.violation(qd) >= -tolerance)


def pair_list(rows: CollisionRows, indices: Sequence[int]) -> str:
    """``"a | b (d = x mm), c | d (d = y mm)"``: the pairs of ``indices``, for messages."""
    return ", ".join(rows.describe(int(i)) for i in indices)


def record_distances(info: SolveInfo, rows: CollisionRows) -> None:
    """``info.minimum_distance`` and ``info.closest_pair`` from the rows' measurement."""
    info.minimum_distance = rows.minimum_distance
    info.closest_pair = rows.closest_pair


def report_held_back(info: SolveInfo, names: Sequence[str], described: str,
                     twist_missed: bool) -> None:
    """``info.active_pairs = names``; a step that misses the twist while a pair is held is
    ``least_squares`` and its message names the pairs (``described``)."""
    info.active_pairs = tuple(names)
    if twist_missed and names:
        plural = "s" if len(names) > 1 else ""
        info.report(StepStatus.LEAST_SQUARES, f"held back by collision pair{plural} {described}")


def report_conflict(info: SolveInfo, rows: CollisionRows, indices: Sequence[int]) -> None:
    """``constraint_degraded`` naming the pairs (``indices``) the least-residual command
    holds at their bound while the constraint rows cannot all be held."""
    if len(indices):
        plural = "s" if len(indices) > 1 else ""
        info.report(StepStatus.CONSTRAINT_DEGRADED,
                    f"collision pair{plural} {pair_list(rows, indices)} cannot be kept apart "
                    "together with the constraint rows")
