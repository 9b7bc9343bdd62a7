"""The general CJM: any set of constraint rows, any chain (docs/design.md section 4).

::

    A qd = b  ->  qd = qd_0 + N y,  N = null(A),  qd_0 = A^+ b
    y = (J_e N)^+ (V_e - J_e qd_0)    (damped, eq 35), posture in null(J_e N)

``N`` spans the joint velocities that leave every constrained point still: the
null-space counterpart of the analytical form's structure matrix ``S``.

Collision rows held at their bound come last in ``A`` (docs/design.md section 18.4). When
they conflict with the rows before them (``A`` rank-deficient with a least-squares
residual), those are held exactly and the collision rows by least squares in their null
space, a second level::

    qd_1 = A_1^+ b_1 + N_1 (A_2 N_1)^+ (b_2 - A_2 A_1^+ b_1)

and ``b_2`` becomes ``A_2 qd_1``: the stacked rows are consistent again and the stacked
solution is ``qd_1`` (it lies in the row space of ``A``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..base import StepStatus
from ..linalg import DampingPolicy, damped_least_squares, nullspace
from .analytical import report_task_solution
from .report import Event, StepReport
from .tolerances import CONFLICT_RESIDUAL


def solve_general(rows: np.ndarray, rows_rhs: np.ndarray, ee_jacobian: np.ndarray,
                  twist: np.ndarray, policy: DampingPolicy,
                  posture_velocity: np.ndarray | None, report: StepReport,
                  pairs: Sequence[int] = ()) -> np.ndarray:
    """``qd`` holding ``rows qd = rows_rhs`` first, then the twist, then the posture.

    The last ``len(pairs)`` rows are collision rows (``pairs``: their indices in the
    step's :class:`~constraints.collision.CollisionRows`); in a conflict they yield to
    the others and their entries of ``rows_rhs`` are set, in place, to what they get.
    """
    null_basis, rows_pinv, rank = nullspace(rows)
    qd = rows_pinv @ rows_rhs
    if rank < rows.shape[0]:
        residual = float(np.max(np.abs(rows @ qd - rows_rhs)))
        if residual > CONFLICT_RESIDUAL and pairs:
            hold_pairs_below(rows, rows_rhs, pairs, report)
            qd = rows_pinv @ rows_rhs
        elif residual > CONFLICT_RESIDUAL:
            report.event(Event.CONFLICT, StepStatus.CONSTRAINT_DEGRADED, rank, rows.shape[0], residual)
    if null_basis.shape[1] > 0:
        cjm = ee_jacobian @ null_basis
        cjm_rhs = twist - ee_jacobian @ qd
        solution = damped_least_squares(cjm, cjm_rhs, policy)
        qd += null_basis @ solution.x
        report_task_solution(solution, cjm, cjm_rhs, report)
        if posture_velocity is not None and solution.rank < null_basis.shape[1]:
            posture = null_basis.T @ posture_velocity
            posture -= solution.row_space.T @ (solution.row_space @ posture)
            qd += null_basis @ posture
    elif np.any(twist):
        report.event(Event.NO_FREE_JOINT, StepStatus.LEAST_SQUARES)
    report.equality_residual = (max(map(abs, (rows @ qd - rows_rhs).tolist())) if rows.size else 0.0)
    report.method = "general"
    return qd


def hold_pairs_below(rows: np.ndarray, rows_rhs: np.ndarray, pairs: Sequence[int],
                     report: StepReport) -> None:
    """The second level of the module docstring: ``rows_rhs``'s last ``len(pairs)``
    entries (the collision rows') set to ``A_2 qd_1``; a pair left short of its bound
    is ``PAIR_CONFLICT`` (constraint_degraded), a conflict among the rows before them
    ``CONFLICT``."""
    first = rows.shape[0] - len(pairs)
    level_one, level_one_rhs, second = rows[:first], rows_rhs[:first], rows[first:]
    basis, level_one_pinv, rank = nullspace(level_one)
    qd = level_one_pinv @ level_one_rhs
    if rank < first:
        residual = float(np.max(np.abs(level_one @ qd - level_one_rhs)))
        if residual > CONFLICT_RESIDUAL:
            report.event(Event.CONFLICT, StepStatus.CONSTRAINT_DEGRADED, rank, first, residual)
    if basis.shape[1]:
        _, second_pinv, _ = nullspace(second @ basis)
        qd += basis @ (second_pinv @ (rows_rhs[first:] - second @ qd))
    held = second @ qd
    for pair, bound, value in zip(pairs, rows_rhs[first:].tolist(), held.tolist()):
        if bound - value > CONFLICT_RESIDUAL:
            report.event(Event.PAIR_CONFLICT, StepStatus.CONSTRAINT_DEGRADED, pair, bound - value)
    rows_rhs[first:] = held
