"""The equality rows eliminated from a stage: the QP over ``null(A)`` (docs/design.md 10.2).

A stage ``min 1/2 x'Hx + g'x  s.t.  A x = b,  l <= C x <= u,  lower <= x <= upper`` is
solved, where a bound of the box is nearly a combination of the rows ``A``, as::

    x = x_p + N y,    x_p = A^+ b,   N = null(A) (orthonormal)
    min 1/2 y' (N'HN) y + (N'(H x_p + g))' y
    s.t.  lower - x_p <= N y <= upper - x_p,    l - C x_p <= C N y <= u - C x_p

with every inequality row of ``y`` divided by its norm. A joint ``i`` the rows almost fix
(``|N_i| = dist(e_i, rowspace A)`` small) has a bound nearly parallel to them: held
together, the two leave a constraint on the other joints of size ``|N_i|`` (at a singular
configuration the plane's row ``[-0.82, 1e-8, ..., -3e-8, ...]`` and the bound of joint 0
leave ``1e-8 (qd_1 + qd_2 + qd_3) - 3e-8 qd_4 <= 0``). A backend's primal tolerance
``tau`` on the two rows lets that constraint slip by ``tau / |N_i|`` (0.01 rad/s at
``tau = 1e-10``), and daqp's active set sees the pair as linearly dependent and stops
"infeasible". Normalised, the row ``N_i y / |N_i|`` is the constraint itself, held to
``tau``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..base import EQUALITY_TOLERANCE, SolverError
from ..numerics import INFINITE_BOUND
from ..optimization.problem import QPSolution, QuadraticProgram

#: A bounded joint whose row of ``null(A)`` is shorter than this is nearly fixed by the
#: equality rows (its bound within this angle of their row space): the stage is then
#: solved over ``null(A)`` (:func:`eliminated`). Above it the pair is well posed for the
#: backends as it stands (``tau / |N_i|`` below 1e-7 rad/s at ``tau = 1e-10``).
NEARLY_FIXED = 1e-3

#: Rows of ``null(A)`` at or below this norm are zero: the rows fix that joint (or that
#: inequality row), whose bound is then a check on ``x_p`` alone.
FIXED = 1e-12


class ReducedStage(NamedTuple):
    """The stage over ``y`` and what maps its answer back to ``x``."""

    problem: QuadraticProgram
    particular: np.ndarray
    basis: np.ndarray
    #: per bounded joint / per inequality row: ``1 / |N_i|`` (its row of ``y`` was divided
    #: by ``|N_i|``), or 0 where the rows fix it (no row of ``y``)
    box_scale: np.ndarray | None
    row_scale: np.ndarray | None


def nearly_fixed(problem: QuadraticProgram, null_basis: np.ndarray) -> bool:
    """Whether a bounded joint is nearly fixed by the equality rows ``A`` of ``problem``:
    its row of ``null_basis`` (``N = null(A)``, orthonormal) shorter than
    :data:`NEARLY_FIXED`."""
    if problem.equality_matrix is None or problem.lower is None:
        return False
    squared_lengths = (null_basis * null_basis).sum(axis=1)
    # most steps end here; the lengths and a Python min take 18.7k instructions, einsum
    # and ndarray.min 26.0k (callgrind of 20,000 calls)
    if min(squared_lengths.tolist()) >= NEARLY_FIXED ** 2:
        return False
    nearly = squared_lengths < NEARLY_FIXED ** 2
    return bool(np.any(nearly & ((problem.lower > -INFINITE_BOUND)
                                 | (problem.upper < INFINITE_BOUND))))


def eliminated(problem: QuadraticProgram, basis: np.ndarray) -> ReducedStage:
    """The stage over ``y``, ``x = x_p + N y`` (module docstring); ``basis`` is ``N``.

    Raises :class:`SolverError` when the equality rows are inconsistent beyond
    ``EQUALITY_TOLERANCE``, or when a bound on something they fix is missed by ``x_p``
    beyond it (no ``y`` can mend either).
    """
    A, b = problem.equality_matrix, problem.equality_rhs
    assert A is not None and b is not None
    particular = np.linalg.lstsq(A, b, rcond=None)[0]
    if float(np.max(np.abs(A @ particular - b))) > EQUALITY_TOLERANCE:
        raise SolverError("the equality rows are inconsistent")
    blocks: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    box_scale = row_scale = None
    if problem.lower is not None:
        box_rows, box_low, box_high, box_scale = _normalised(basis, particular, problem.lower,
                                                             problem.upper)
        blocks.append((box_rows, box_low, box_high))
    if problem.rows is not None:
        rows, low, high, row_scale = _normalised(problem.rows @ basis, problem.rows @ particular,
                                                 problem.rows_lower, problem.rows_upper)
        blocks.append((rows, low, high))
    hessian = basis.T @ problem.hessian @ basis
    hessian = 0.5 * (hessian + hessian.T)
    gradient = basis.T @ (problem.hessian @ particular + problem.gradient)
    reduced = QuadraticProgram(
        hessian, gradient, rows=np.vstack([rows for rows, _, _ in blocks]) if blocks else None,
        rows_lower=np.concatenate([low for _, low, _ in blocks]) if blocks else None,
        rows_upper=np.concatenate([high for _, _, high in blocks]) if blocks else None,
        curvature=problem.curvature, semidefinite=problem.semidefinite)
    return ReducedStage(reduced, particular, basis, box_scale, row_scale)


def _normalised(rows: np.ndarray, at_particular: np.ndarray, lower: np.ndarray,
                upper: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``lower - r <= rows y <= upper - r`` (``r = at_particular``) with each row divided
    by its norm, infinite bounds kept infinite; rows of norm at most :data:`FIXED` are
    dropped after checking ``r`` against their bounds. Returns the rows, their bounds and
    ``1 / norm`` per row (0 where dropped)."""
    lengths = np.linalg.norm(rows, axis=1)
    kept = lengths > FIXED
    fixed = ~kept
    if np.any(at_particular[fixed] < lower[fixed] - EQUALITY_TOLERANCE) or np.any(
            at_particular[fixed] > upper[fixed] + EQUALITY_TOLERANCE):
        raise SolverError("a bound on what the equality rows fix is missed")
    scale = np.zeros(lengths.size)
    scale[kept] = 1.0 / lengths[kept]
    low = np.where(lower > -INFINITE_BOUND, (lower - at_particular) * scale, -INFINITE_BOUND)
    high = np.where(upper < INFINITE_BOUND, (upper - at_particular) * scale, INFINITE_BOUND)
    return rows[kept] * scale[kept, None], low[kept], high[kept], scale


def restored(stage: ReducedStage, solution: QPSolution) -> QPSolution:
    """``x = x_p + N y`` and the multipliers of the original box and rows
    (``mu / |N_i|``, as ``N_i y / |N_i| <= c / |N_i|`` is ``x_i <= upper_i`` divided by
    ``|N_i|``; 0 for a bound the rows fix)."""
    x = stage.particular + stage.basis @ solution.x
    multipliers = np.zeros(0) if solution.row_multipliers is None else solution.row_multipliers
    box = rows = None
    start = 0
    if stage.box_scale is not None:
        box, start = _scattered(stage.box_scale, multipliers, start)
    if stage.row_scale is not None:
        rows, start = _scattered(stage.row_scale, multipliers, start)
    return QPSolution(x, box, rows)


def _scattered(scale: np.ndarray, multipliers: np.ndarray, start: int
               ) -> tuple[np.ndarray, int]:
    """The multipliers of one block of kept rows, back on every original row."""
    kept = scale > 0.0
    values = np.zeros(scale.size)
    end = start + int(np.count_nonzero(kept))
    values[kept] = multipliers[start:end] * scale[kept]
    return values, end
