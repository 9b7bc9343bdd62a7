"""Joint limits in the CJM: saturation in the null space (SNS), docs/design.md section 9.

Flacco, De Luca, Khatib, "Control of redundant robots under hard joint constraints:
saturation in the null space", IEEE T-RO 2015, Algorithm 1, with the constraint rows as
a hard first priority. Over the free joints ``F`` (the saturated ones ``W`` held at a
bound ``qd_W``)::

    A_F x = b - A_W qd_W                      rows, exact:  x = x_0 + N_F y
    (J_F N_F) y = s V_e - J_W qd_W - J_F x_0  task, scaled by s in [0, 1]

so ``qd(s) = base + s direction`` with ``A base = b`` and ``A direction = 0``: every
iterate holds the rows, and scaling touches only the task. While some joint leaves its
box, the joint that limits the task scale most is saturated at the bound it hits and the
rest solved again. When saturating would cost task directions (the rank of ``J_F N_F``
drops), the best scale found so far is kept instead. A joint held at a *position* bound
is treated as locked, the task solved over the others (see
:func:`saturate_in_null_space`). If not even the rows fit inside
the box, their right-hand side (drift feedback and feed-forward) is scaled down as
little as needed: the constraint then converges as fast as the limits allow.

This is the saturation without acceleration limits. With them the box is a narrow window
around the previous command and :mod:`controllers.cjm.saturation_walk` saturates around
that command instead (docs/design.md section 12).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..base import TWIST_TOLERANCE
from ..linalg import DampingPolicy, damped_least_squares, nullspace
from .tolerances import AT_BOUND, BOX_MARGIN, ROWS_TOLERANCE, STILL_DIRECTION


@dataclass
class Saturation:
    """The result of :func:`saturate_in_null_space`.

    Attributes
    ----------
    qd : the command, inside the box.
    task_scale : the factor ``s`` of the task (1: the task as asked).
    rows_scale : the factor of the rows' right-hand side (1: the constraints as asked).
    saturated : velocity indices of the joints held at a bound.
    limiting_joint : the joint whose limit sets ``task_scale`` (-1: none).
    task_missed : ``J_e qd`` differs from ``task_scale V_e`` (a least-squares task).
    sigma_min, damping : of the DLS of the task over the free joints that gave ``qd``
        (NaN and 0 when no task was solved: no free direction, or the rows scaled).
    """

    qd: np.ndarray
    task_scale: float
    rows_scale: float
    saturated: tuple[int, ...]
    limiting_joint: int
    task_missed: bool
    sigma_min: float = float("nan")
    damping: float = 0.0


@dataclass
class _Split:
    """``qd(s) = base + s direction`` for one saturated set."""

    base: np.ndarray
    direction: np.ndarray
    rows_residual: float
    task_rank: int
    sigma_min: float = float("nan")
    damping: float = 0.0


def solve_over_free(rows: np.ndarray, rows_rhs: np.ndarray, jacobian: np.ndarray,
                    twist: np.ndarray, free: np.ndarray, held: np.ndarray,
                    policy: DampingPolicy) -> _Split:
    """The rows exactly, then the task, over the free joints; ``held`` on the others
    (``held`` is zero on the free joints, so products with it need no masks)."""
    rhs = rows_rhs - rows @ held
    rows_free = rows[:, free]
    null_basis, rows_pinv, _ = nullspace(rows_free)
    x_0 = rows_pinv @ rhs
    rows_residual = float(np.max(np.abs(rows_free @ x_0 - rhs), initial=0.0))
    base = held.copy()
    base[free] = x_0
    direction = np.zeros_like(held)
    task_rank, sigma_min, damping = 0, float("nan"), 0.0
    if null_basis.shape[1]:
        cjm = jacobian[:, free] @ null_basis
        task_rhs = np.column_stack([twist, -(jacobian @ base)])
        solution = damped_least_squares(cjm, task_rhs, policy)
        base[free] += null_basis @ solution.x[:, 1]
        direction[free] = null_basis @ solution.x[:, 0]
        task_rank, sigma_min, damping = solution.rank, solution.sigma_min, solution.damping
    return _Split(base, direction, rows_residual, task_rank, sigma_min, damping)


def task_scale_limit(base: np.ndarray, direction: np.ndarray, lower: np.ndarray,
                     upper: np.ndarray, free: np.ndarray) -> tuple[float, int]:
    """The largest ``s`` in [0, 1] with ``base + s direction`` in the box on the free
    joints (-inf when no ``s >= 0`` fits), and the joint that limits it (-1 if none).

    Flacco et al.'s *getTaskScalingFactor*: per joint the interval of ``s`` that keeps it
    inside, intersected over the free joints. A joint whose ``base`` is at a bound up to
    its rounding (:func:`gap_to_bound`) bounds ``s`` at exactly 0, so that among joints
    at their limits (several at once, at a configuration on the limits) the lowest index
    is the critical one whatever the last bits of ``base``; a ``direction`` entry within
    the rounding of the direction (a joint the task does not move) counts as 0. The
    choice, and so the joints saturated, the barriers that follow and the status, must
    not depend on rounding (docs/design.md section 9).
    """
    smallest_max, critical, largest_min, needs_more = np.inf, -1, -np.inf, -1
    noise = float(np.max(np.abs(base), initial=0.0))
    still = max(STILL_DIRECTION, AT_BOUND * float(np.max(np.abs(direction), initial=0.0)))
    for i in np.flatnonzero(free).tolist():
        a, b = direction[i], base[i]
        to_lower, to_upper = gap_to_bound(lower[i], b, noise), gap_to_bound(upper[i], b, noise)
        if abs(a) > still:
            low, high = to_lower / a, to_upper / a
            if a < 0.0:
                low, high = high, low
        elif to_lower <= 0.0 <= to_upper:
            continue
        else:
            low, high = np.inf, -np.inf  # outside whatever the scale
        if high < smallest_max:
            smallest_max, critical = high, i
        if low > largest_min:
            largest_min, needs_more = low, i
    largest = min(1.0, smallest_max) + 0.0  # + 0.0: no -0 (a joint at its bound: s = 0)
    if largest_min > largest:  # joint needs_more is outside for every s in [0, 1]
        return -np.inf, needs_more
    if largest < 0.0:
        return -np.inf, critical
    return largest, critical


def gap_to_bound(bound: float, base: float, noise: float) -> float:
    """``bound - base``, exactly 0 when within the rounding of the base
    (:data:`controllers.cjm.tolerances.AT_BOUND`)."""
    gap = bound - base
    return 0.0 if abs(gap) <= AT_BOUND * (1.0 + abs(bound) + noise) else gap


def _inside(qd: np.ndarray, box: tuple[np.ndarray, np.ndarray]) -> bool:
    return bool((qd >= box[0]).all() and (qd <= box[1]).all())


def saturate_in_null_space(rows: np.ndarray, rows_rhs: np.ndarray, jacobian: np.ndarray,
                           twist: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                           velocity_limit: np.ndarray, policy: DampingPolicy) -> Saturation:
    """``qd`` inside ``[lower, upper]`` holding the rows first, the twist second.

    A joint whose *velocity* limit binds slows the task: Flacco et al.'s scaling, the
    direction of the twist kept. A joint whose *position* bound binds (it is at, or a
    period away from, a position limit) is held there like a locked joint and the task
    is solved over the others, in the least-squares sense if they cannot give all of it
    (as the QP does); scaling for it would freeze the arm as the bound shrinks to zero.
    """
    nv = jacobian.shape[1]
    free = np.ones(nv, dtype=bool)
    held = np.zeros(nv)
    box = (lower - BOX_MARGIN * (1.0 + np.abs(lower)), upper + BOX_MARGIN * (1.0 + np.abs(upper)))
    scaled: tuple[float, np.ndarray, np.ndarray, int] | None = None  # scale, free, held, joint
    reference_rank = None  # the task rank before any velocity saturation
    for _ in range(nv + 1):
        split = solve_over_free(rows, rows_rhs, jacobian, twist, free, held, policy)
        reference_rank = split.task_rank if reference_rank is None else reference_rank
        if split.rows_residual > ROWS_TOLERANCE:
            break  # too few free joints left for the rows
        if split.task_rank < reference_rank and scaled is not None:
            break  # Flacco et al.: keep the best scale found with every task direction
        qd = split.base + split.direction
        if _inside(qd, box):
            return _result(qd, 1.0, 1.0, free, -1, jacobian, twist, split)
        scale, critical = task_scale_limit(split.base, split.direction, lower, upper, free)
        if critical < 0:
            break
        bound = upper[critical] if qd[critical] > upper[critical] else lower[critical]
        held[critical] = bound
        free[critical] = False
        if abs(bound) < velocity_limit[critical] * (1.0 - BOX_MARGIN):  # a position bound
            reference_rank, scaled = None, None
        elif scale >= 0.0 and (scaled is None or scale > scaled[0]):
            candidate_free, candidate_held = free.copy(), held.copy()
            candidate_free[critical], candidate_held[critical] = True, 0.0  # it is free there
            scaled = (scale, candidate_free, candidate_held, critical)
        if not free.any():
            break
    if scaled is not None:
        scale, free, held, critical = scaled
        split = solve_over_free(rows, rows_rhs, jacobian, twist, free, held, policy)
        return _result(split.base + scale * split.direction, scale, 1.0, free, critical,
                       jacobian, twist, split)
    return _scale_rows(rows, rows_rhs, lower, upper, jacobian, twist)


def _result(qd: np.ndarray, task_scale: float, rows_scale: float, free: np.ndarray,
            limiting_joint: int, jacobian: np.ndarray, twist: np.ndarray,
            split: _Split | None = None) -> Saturation:
    achieved = jacobian @ qd
    tolerance = TWIST_TOLERANCE * (1.0 + float(np.max(np.abs(twist))))
    missed = float(np.max(np.abs(achieved - task_scale * twist))) > tolerance
    return Saturation(qd, task_scale, rows_scale, tuple(np.flatnonzero(~free).tolist()),
                      limiting_joint, missed,
                      *((split.sigma_min, split.damping) if split else (float("nan"), 0.0)))


def _scale_rows(rows: np.ndarray, rows_rhs: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                jacobian: np.ndarray, twist: np.ndarray) -> Saturation:
    """No task, and the rows' minimum-norm correction ``r A^+ b`` from rest, scaled by the
    largest ``r`` that fits the box."""
    _, rows_pinv, _ = nullspace(rows)
    correction = rows_pinv @ rows_rhs
    everything = np.ones(correction.size, dtype=bool)
    scale, _ = task_scale_limit(np.zeros(correction.size), correction, lower, upper, everything)
    scale = max(scale, 0.0)  # -inf: a joint past its limit; the caller clips
    return _result(scale * correction, 0.0, scale, everything, -1, jacobian, twist)
