"""Any other backend through ``qpsolvers`` (two-sided rows as two one-sided blocks)."""

from __future__ import annotations

import math

import numpy as np
import qpsolvers
import scipy.sparse

from ..base import SolverError
from ..numerics import INFINITE_BOUND
from ..optimization.budget import StepBudget
from ..optimization.problem import QPSolution, QuadraticProgram

#: Backends that take sparse matrices (given dense ones, qpsolvers converts and warns).
SPARSE_SOLVERS = frozenset({"osqp", "scs", "clarabel", "highs", "piqp", "qpalm"})


def solve_with_qpsolvers(problem: QuadraticProgram, solver: str, settings: dict,
                         budget: StepBudget) -> QPSolution:
    """``problem`` solved by ``qpsolvers.solve_problem`` with the backend ``solver``.

    OSQP gets what is left of the step's budget as its own time limit; a solve stopped by
    a limit raises the budget's error, any other failure a :class:`SolverError`. The
    rows' multipliers are recombined from the two one-sided blocks.
    """
    inequalities, bounds, blocks = [], [], []
    if problem.rows is not None:
        for sign, limit in ((1.0, problem.rows_upper), (-1.0, -problem.rows_lower)):
            finite = np.flatnonzero(limit < INFINITE_BOUND)
            if finite.size:
                inequalities.append(sign * problem.rows[finite])
                bounds.append(limit[finite])
                blocks.append((sign, finite))
    G = np.vstack(inequalities) if inequalities else None
    h = np.concatenate(bounds) if bounds else None
    P, A = problem.hessian, problem.equality_matrix
    if solver in SPARSE_SOLVERS:
        P = scipy.sparse.csc_matrix(P)
        A = None if A is None else scipy.sparse.csc_matrix(A)
        G = None if G is None else scipy.sparse.csc_matrix(G)
    qp = qpsolvers.Problem(P, problem.gradient, G, h, A, problem.equality_rhs,
                           lb=problem.lower, ub=problem.upper)
    left = budget.remaining(solver)
    if solver == "osqp" and math.isfinite(left):  # one solve bounded by what is left
        settings = {**settings, "time_limit": left}
    try:
        solution = qpsolvers.solve_problem(qp, solver=solver, **settings)
    except Exception as error:  # backends raise their own types
        raise SolverError(f"{solver} raised {type(error).__name__}: {error}") from error
    if not solution.found or solution.x is None:
        status = str(getattr(solution.extras.get("info"), "status", ""))
        if "time limit" in status or "maximum iterations" in status:
            raise budget.exceeded(solver, status)
        raise SolverError(f"{solver} found no solution "
                          f"({status or 'infeasible or not converged'})")
    row_multipliers = None
    if problem.rows is not None:
        row_multipliers = np.zeros(problem.rows.shape[0])
        start = 0
        stacked = np.zeros(0) if solution.z is None else np.asarray(solution.z, dtype=float)
        for sign, finite in blocks:
            if stacked.size:
                row_multipliers[finite] += sign * stacked[start:start + finite.size]
            start += finite.size
    box_multipliers = None
    if problem.lower is not None and solution.z_box is not None:
        box_multipliers = np.asarray(solution.z_box, dtype=float)
    return QPSolution(np.asarray(solution.x, dtype=float), box_multipliers, row_multipliers)
