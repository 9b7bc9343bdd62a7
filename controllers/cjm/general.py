"""The general CJM: any set of constraint rows, any chain (docs/design.md section 4).

::

    A qd = b  ->  qd = qd_0 + N y,  N = null(A),  qd_0 = A^+ b
    y = (J_e N)^+ (V_e - J_e qd_0)    (damped, eq 35), posture in null(J_e N)

``N`` spans the joint velocities that leave every constrained point still: the
null-space counterpart of the analytical form's structure matrix ``S``.
"""

from __future__ import annotations

import numpy as np

from ..base import StepStatus
from ..linalg import DampingPolicy, damped_least_squares, nullspace
from .analytical import report_task_solution
from .report import Event, ReportBuilder
from .tolerances import CONFLICT_RESIDUAL

def solve_general(rows: np.ndarray, rows_rhs: np.ndarray, ee_jacobian: np.ndarray,
                  twist: np.ndarray, policy: DampingPolicy,
                  posture_velocity: np.ndarray | None, report: ReportBuilder) -> np.ndarray:
    """``qd`` holding ``rows qd = rows_rhs`` first, then the twist, then the posture."""
    null_basis, rows_pinv, rank = nullspace(rows)
    qd = rows_pinv @ rows_rhs
    if rank < rows.shape[0]:
        residual = float(np.max(np.abs(rows @ qd - rows_rhs)))
        if residual > CONFLICT_RESIDUAL:
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
