"""Joint limits in the CJM: saturation in the null space (SNS), docs/design.md section 8.

Flacco, Lee, De Luca, Khatib, "Control of redundant robots under hard joint constraints:
saturation in the null space", IEEE T-RO 2015, Algorithm 1, with the constraint rows as
a hard first priority. Over the free joints ``F`` (the saturated ones ``W`` held at a
bound ``qd_W``)::

    A_F x = b - A_W qd_W                      rows, exact:  x = x_0 + N_F y
    (J_F N_F) y = s V_e - J_W qd_W - J_F x_0  task, scaled by s in [0, 1]

so ``qd(s) = base + s direction`` with ``A base = b`` and ``A direction = 0``: every
iterate holds the rows, and scaling touches only the task. While some joint leaves its
box, the joint that limits the task scale most is saturated at the bound it hits and the
rest solved again. When saturating would cost task directions (the rank of ``J_F N_F``
drops), the best scale found so far is kept instead. If not even the rows fit inside
the box, their right-hand side (drift feedback and feed-forward) is scaled down as
little as needed: the constraint then converges as fast as the limits allow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..linalg import DampingPolicy, damped_least_squares, nullspace

#: The rows count as held over the free joints up to this residual (m/s).
ROWS_TOLERANCE = 1e-9


@dataclass
class Saturation:
    """The result of :func:`saturate_in_null_space`.

    Attributes
    ----------
    qd : the command, inside the box.
    task_scale : the factor ``s`` of the task (1: the task as asked).
    rows_scale : the factor of the rows' right-hand side (1: the constraints as asked).
    saturated : velocity indices of the joints held at a bound.
    task_missed : ``J_e qd`` differs from ``task_scale V_e`` (a least-squares task).
    """

    qd: np.ndarray
    task_scale: float
    rows_scale: float
    saturated: tuple[int, ...]
    task_missed: bool


@dataclass
class _Split:
    """``qd(s) = base + s direction`` for one saturated set."""

    base: np.ndarray
    direction: np.ndarray
    rows_residual: float
    task_rank: int


def _solve_over_free(rows: np.ndarray, rows_rhs: np.ndarray, jacobian: np.ndarray,
                     twist: np.ndarray, free: np.ndarray, held: np.ndarray,
                     policy: DampingPolicy) -> _Split:
    """The rows exactly, then the task, over the free joints; ``held`` on the others."""
    fixed = ~free
    rhs = rows_rhs - rows[:, fixed] @ held[fixed]
    rows_free = rows[:, free]
    null_basis, rows_pinv, _ = nullspace(rows_free)
    x_0 = rows_pinv @ rhs
    rows_residual = float(np.max(np.abs(rows_free @ x_0 - rhs), initial=0.0))
    base = held.copy()
    base[free] = x_0
    direction = np.zeros_like(held)
    task_rank = 0
    if null_basis.shape[1]:
        jacobian_free = jacobian[:, free]
        cjm = jacobian_free @ null_basis
        task_rhs = np.column_stack([twist, -(jacobian[:, fixed] @ held[fixed]) - jacobian_free @ x_0])
        solution = damped_least_squares(cjm, task_rhs, policy)
        base[free] += null_basis @ solution.x[:, 1]
        direction[free] = null_basis @ solution.x[:, 0]
        task_rank = solution.rank
    return _Split(base, direction, rows_residual, task_rank)


def task_scale_limit(base: np.ndarray, direction: np.ndarray, lower: np.ndarray,
                     upper: np.ndarray, free: np.ndarray) -> tuple[float, int]:
    """The largest ``s`` in [0, 1] with ``base + s direction`` in the box on the free
    joints (-inf when no ``s >= 0`` fits), and the joint that limits it (-1 if none).

    Flacco et al.'s *getTaskScalingFactor*: per joint the interval of ``s`` that keeps it
    inside, intersected over the free joints.
    """
    smallest_max, critical, largest_min = np.inf, -1, -np.inf
    for i in np.flatnonzero(free).tolist():
        a, b = direction[i], base[i]
        if abs(a) > 1e-12:
            low, high = (lower[i] - b) / a, (upper[i] - b) / a
            if a < 0.0:
                low, high = high, low
        elif lower[i] <= b <= upper[i]:
            continue
        else:
            low, high = np.inf, -np.inf  # outside whatever the scale
        if high < smallest_max:
            smallest_max, critical = high, i
        largest_min = max(largest_min, low)
    if largest_min > smallest_max or smallest_max < 0.0:
        return -np.inf, critical
    return min(1.0, smallest_max), critical


def _inside(qd: np.ndarray, lower: np.ndarray, upper: np.ndarray, tolerance: float = 1e-12) -> bool:
    return bool(np.all(qd >= lower - tolerance * (1.0 + np.abs(lower)))
                and np.all(qd <= upper + tolerance * (1.0 + np.abs(upper))))


def saturate_in_null_space(rows: np.ndarray, rows_rhs: np.ndarray, jacobian: np.ndarray,
                           twist: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                           policy: DampingPolicy) -> Saturation:
    """``qd`` inside ``[lower, upper]`` holding the rows first, the twist scaled second."""
    nv = jacobian.shape[1]
    free = np.ones(nv, dtype=bool)
    held = np.zeros(nv)
    best: tuple[float, np.ndarray, np.ndarray] | None = None  # (scale, free, held), full rank
    full_rank = None
    for _ in range(nv + 1):
        split = _solve_over_free(rows, rows_rhs, jacobian, twist, free, held, policy)
        full_rank = split.task_rank if full_rank is None else full_rank
        if split.rows_residual > ROWS_TOLERANCE:
            break  # too few free joints left for the rows
        rank_lost = split.task_rank < full_rank
        if rank_lost and best is not None:
            break  # Flacco et al.: keep the best scale found with every task direction
        qd = split.base + split.direction
        if _inside(qd, lower, upper):
            return _result(qd, 1.0, 1.0, free, jacobian, twist)
        scale, critical = task_scale_limit(split.base, split.direction, lower, upper, free)
        if scale >= 0.0 and not rank_lost and (best is None or scale > best[0]):
            best = (scale, free.copy(), held.copy())
        if critical < 0:
            break
        held[critical] = upper[critical] if qd[critical] > upper[critical] else lower[critical]
        free[critical] = False
        if not free.any():
            break
    if best is not None:
        scale, free, held = best
        split = _solve_over_free(rows, rows_rhs, jacobian, twist, free, held, policy)
        return _result(split.base + scale * split.direction, scale, 1.0, free, jacobian, twist)
    return _scale_rows(rows, rows_rhs, lower, upper, jacobian, twist)


def _result(qd: np.ndarray, task_scale: float, rows_scale: float, free: np.ndarray,
            jacobian: np.ndarray, twist: np.ndarray) -> Saturation:
    task_residual = float(np.max(np.abs(jacobian @ qd - task_scale * twist)))
    achieved = task_residual <= 1e-9 * (1.0 + float(np.max(np.abs(twist))))
    return Saturation(qd, task_scale, rows_scale, tuple(np.flatnonzero(~free).tolist()),
                      not achieved)


def _scale_rows(rows: np.ndarray, rows_rhs: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                jacobian: np.ndarray, twist: np.ndarray) -> Saturation:
    """No task, and the rows' correction scaled by the largest factor that fits the box."""
    _, rows_pinv, _ = nullspace(rows)
    correction = rows_pinv @ rows_rhs
    everything = np.ones(correction.size, dtype=bool)
    scale, _ = task_scale_limit(np.zeros_like(correction), correction, lower, upper, everything)
    scale = max(scale, 0.0)  # -inf: a joint past its limit; the caller clips
    return _result(scale * correction, 0.0, scale, everything, jacobian, twist)
