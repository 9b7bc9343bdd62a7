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


def closest_rows(rows: CollisionRows, indices: Sequence[int] | np.ndarray) -> list[int]:
    """``indices`` with one row per pair name (a link pair has a row per geometry pair):
    the nearest, in the order the names first appear."""
    nearest: dict[str, int] = {}
    for index in map(int, indices):
        name = rows.pairs[index]
        if name not in nearest or rows.distances[index] < rows.distances[nearest[name]]:
            nearest[name] = index
    return list(nearest.values())


def pair_names(rows: CollisionRows, indices: Sequence[int] | np.ndarray) -> tuple[str, ...]:
    """The pair names of ``indices``, each once."""
    return tuple(rows.pairs[i] for i in closest_rows(rows, indices))


def pair_list(rows: CollisionRows, indices: Sequence[int] | np.ndarray) -> str:
    """``"a | b (d = x mm), c | d (d = y mm)"``: the pairs of ``indices``, each once at its
    nearest row, for messages."""
    return ", ".join(rows.describe(i) for i in closest_rows(rows, indices))


def describe_pair(rows: CollisionRows, name: str) -> str:
    """``name`` with its nearest row's distance (``"a | b (d = x mm)"``), or the name alone
    when no row has it."""
    indices = [i for i, pair in enumerate(rows.pairs) if pair == name]
    return pair_list(rows, indices) if indices else name


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


def report_conflict(info: SolveInfo, rows: CollisionRows, indices: Sequence[int] | np.ndarray) -> None:
    """``constraint_degraded`` naming the pairs (``indices``) the least-residual command
    holds at their bound while the constraint rows cannot all be held."""
    if len(indices):
        plural = "s" if len(pair_names(rows, indices)) > 1 else ""
        info.report(StepStatus.CONSTRAINT_DEGRADED,
                    f"collision pair{plural} {pair_list(rows, indices)} cannot be kept apart "
                    "together with the constraint rows")
