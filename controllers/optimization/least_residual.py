"""When the constraint rows conflict with the joint box: the least residual they can keep
(docs/design.md section 10.6).

A hole that jumps 5.5 cm asks its link for 5.5 m/s across the axis (``b = -K e``, K = 100):
no joint box holds ``A qd = b``, and a QP with those rows hard is infeasible. The
optimisers then solve in two steps, as the CJM scales its correction (section 9):

1. **Least residual.** Over ``x = [qd; t]`` (``t``: one slack per barrier row)::

       min 1/2 (|A qd - b|^2 + |t|^2) / s     s.t.  G qd - t <= h,  t >= 0,  box on qd

   ``s = |A|_F^2 / k`` (the rows' mean squared singular value) keeps the Hessian of order
   one. ``A qd`` and ``t`` are the same at every minimiser (the objective is strictly
   convex in them).
2. **Held rows.** With ``qd*`` clipped to the box, the rows are held at what it achieves,
   ``A qd = A qd*`` and ``G qd <= max(h, G qd*)``, and the task and posture stages run
   under them as usual: the lexicographic priorities are kept, and the rows are as close
   to ``b`` as the limits allow. The step reports ``constraint_degraded`` with the
   residual ``max |A qd - b|`` (m/s).

The held equalities are passed as ``U_r^T A qd = U_r^T A qd*`` (``A = U S V^T``, rank
``r``): consistent and of full row rank, also when conflicting constraints make ``A``
rank deficient.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..numerics import numerical_rank, svd


def held_note(residual: float) -> str:
    """The step's message when the rows are held at their least residual (m/s)."""
    return (f"constraint rows conflict with the joint limits or barriers: held at their "
            f"least residual, {residual:.2e} m/s")


class LeastResidualProblem(NamedTuple):
    """The QP of step 1 over ``x = [qd; t]``: ``min 1/2 x'Hx + g'x`` under
    ``rows x <= rows_upper`` and ``lower <= x <= upper`` (``infinite`` stands for no bound).
    ``curvature`` is the smallest non-zero eigenvalue of ``H``; ``semidefinite`` whether
    ``H`` is singular."""

    hessian: np.ndarray
    gradient: np.ndarray
    rows: np.ndarray | None
    rows_lower: np.ndarray | None
    rows_upper: np.ndarray | None
    lower: np.ndarray
    upper: np.ndarray
    curvature: float
    semidefinite: bool


class HeldRows(NamedTuple):
    """Step 2's rows: ``rows qd = rhs`` (None without equalities), the barriers'
    ``G qd <= barrier_bound``, the least-residual command ``qd`` (in the box) and the
    residual it leaves (m/s: the largest of ``|A qd - b|`` and the barriers' slack)."""

    rows: np.ndarray | None
    rhs: np.ndarray | None
    barrier_bound: np.ndarray | None
    qd: np.ndarray
    residual: float


def least_residual_problem(A: np.ndarray | None, b: np.ndarray | None, G: np.ndarray | None,
                           h: np.ndarray | None, lower: np.ndarray, upper: np.ndarray,
                           infinite: float) -> LeastResidualProblem:
    """Step 1's QP for the equality rows ``A qd = b`` and barrier rows ``G qd <= h``."""
    nv = lower.size
    slacks = 0 if G is None else G.shape[0]
    hessian = np.zeros((nv + slacks, nv + slacks))
    gradient = np.zeros(nv + slacks)
    scale, curvature, rank = 1.0, 1.0, 0
    if A is not None:
        values = svd(A)[1]
        scale = max(float(np.vdot(A, A)) / A.shape[0], 1e-300)
        rank = numerical_rank(values)
        curvature = float(values[rank - 1]) ** 2 / scale if rank else 1.0
        hessian[:nv, :nv] = A.T @ A / scale
        gradient[:nv] = -(b @ A) / scale
    rows = rows_lower = rows_upper = None
    if slacks:
        hessian[nv:, nv:] = np.eye(slacks) / scale
        curvature = min(curvature, 1.0 / scale)
        rows = np.hstack([G, -np.eye(slacks)])
        rows_lower, rows_upper = np.full(slacks, -infinite), h.copy()
    return LeastResidualProblem(
        hessian, gradient, rows, rows_lower, rows_upper,
        np.concatenate([lower, np.zeros(slacks)]),
        np.concatenate([upper, np.full(slacks, infinite)]), curvature, rank < nv)


def held_rows(x: np.ndarray, A: np.ndarray | None, b: np.ndarray | None,
              G: np.ndarray | None, h: np.ndarray | None, lower: np.ndarray,
              upper: np.ndarray) -> HeldRows:
    """Step 2's rows from step 1's solution ``x = [qd; t]``."""
    qd = np.clip(x[:lower.size], lower, upper)
    residual, rows, rhs, bound = 0.0, None, None, None
    if A is not None:
        residual = float(np.max(np.abs(A @ qd - b)))
        left, values, _ = svd(A)
        rank = numerical_rank(values)
        rows = left[:, :rank].T @ A
        rhs = rows @ qd
    if G is not None:
        reached = G @ qd
        bound = np.maximum(h, reached)
        residual = max(residual, float(np.max(reached - h)))
    return HeldRows(rows, rhs, bound, qd, residual)
