"""An answer's optimality certificate: its largest KKT residual (docs/design.md 18.7).

For the convex program of :class:`~controllers.optimization.problem.QuadraticProgram`,
``x`` is optimal when multipliers ``y`` (equalities), ``z`` (rows ``C``, positive at an
upper bound, negative at a lower one) and ``w`` (the box, alike) exist with::

    primal:             A x = b,  l <= C x <= u,  lower <= x <= upper
    stationarity:       H x + g + A^T y + C^T z + w = 0
    complementarity:    z_i (u_i - C_i x) = 0 where z_i > 0,  z_i (C_i x - l_i) = 0 where z_i < 0
                        (the same for w and the box)

and ``f(x) - f* <= sum_i |z_i| slack_i + sum_j |w_j| slack_j`` when the other two hold
exactly (weak duality). A backend's own "solved" checks the first two only: at ``rho``
1e-12 to 1e-14 proxqp reported solved 6e-11 to 4e-7 above the optimum of the collision
fuzz's stuck task stage (tests/data/proxqp-flat-task-stage.json), whose tolerance is
1e-11; the residual here of those measured was 5.7e-11 and above. The residual
here is in the problem's own units (the optimisers' problems are normalised to order one).
"""

from __future__ import annotations

import numpy as np

from .problem import QuadraticProgram


def _complementarity(multipliers: np.ndarray, values: np.ndarray, lower: np.ndarray,
                     upper: np.ndarray) -> float:
    """The largest ``|multiplier| * slack`` to the bound its sign names; a zero multiplier
    names no bound (its product with an infinite slack would be NaN, not 0)."""
    named = multipliers != 0.0
    slack = np.where(multipliers > 0.0, upper - values, values - lower)[named]
    return float(np.max(np.abs(multipliers[named]) * np.maximum(slack, 0.0), initial=0.0))


def kkt_residual(problem: QuadraticProgram, x: np.ndarray, equality_multipliers: np.ndarray,
                 row_multipliers: np.ndarray, box_multipliers: np.ndarray | None) -> float:
    """The largest primal, stationarity and complementarity residual of ``x`` and its
    multipliers for ``problem`` (module docstring); 0 for an exact optimum, inf when any
    of them is not finite (nothing certified)."""
    given = [x, equality_multipliers, row_multipliers,
             *(() if box_multipliers is None else (box_multipliers,))]
    if not all(np.all(np.isfinite(values)) for values in given):
        return float("inf")
    residual = _kkt_residual(problem, x, equality_multipliers, row_multipliers,
                             box_multipliers)
    return residual if np.isfinite(residual) else float("inf")


def _kkt_residual(problem: QuadraticProgram, x: np.ndarray, equality_multipliers: np.ndarray,
                  row_multipliers: np.ndarray, box_multipliers: np.ndarray | None) -> float:
    """:func:`kkt_residual` of finite values."""
    stationarity = problem.hessian @ x + problem.gradient
    primal, complementarity = 0.0, 0.0
    if problem.equality_matrix is not None and problem.equality_matrix.shape[0]:
        stationarity += problem.equality_matrix.T @ equality_multipliers
        primal = float(np.max(np.abs(problem.equality_matrix @ x - problem.equality_rhs)))
    if problem.rows is not None and problem.rows.shape[0]:
        values = problem.rows @ x
        stationarity += problem.rows.T @ row_multipliers
        primal = max(primal, float(np.max(values - problem.rows_upper)),
                     float(np.max(problem.rows_lower - values)))
        complementarity = _complementarity(row_multipliers, values, problem.rows_lower,
                                           problem.rows_upper)
    if problem.lower is not None and box_multipliers is not None:
        stationarity += box_multipliers
        primal = max(primal, float(np.max(x - problem.upper)),
                     float(np.max(problem.lower - x)))
        complementarity = max(complementarity, _complementarity(
            box_multipliers, x, problem.lower, problem.upper))
    # numpy's max, which keeps a NaN (Python's passes over one): not certified
    return float(np.max([primal, float(np.max(np.abs(stationarity))), complementarity]))
