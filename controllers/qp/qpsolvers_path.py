"""Any other backend through ``qpsolvers`` (two-sided rows as two one-sided blocks)."""

from __future__ import annotations

import math

import numpy as np
import qpsolvers
import scipy.sparse

from ..base import SolverError
from ..numerics import INFINITE_BOUND
from ..optimization.budget import StepBudget
from ..optimization.kkt import kkt_residual
from ..optimization.problem import QPSolution, QuadraticProgram

#: Backends that take sparse matrices (given dense ones, qpsolvers converts and warns).
SPARSE_SOLVERS = frozenset({"osqp", "scs", "clarabel", "highs", "piqp", "qpalm"})


def solve_with_qpsolvers(problem: QuadraticProgram, solver: str, settings: dict,
                         budget: StepBudget, capped_settings: tuple[dict, ...] = ()
                         ) -> QPSolution:
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
    solution = _solved(qp, solver, settings, budget)
    status = _status(solution)
    for retry in capped_settings if "maximum iterations" in status else ():
        again = _solved(qp, solver, {**settings, **retry}, budget)
        if _status(again) == "" and _certified(problem, again, blocks, settings):
            solution, status = again, ""
            break
    if status:
        if "time limit" in status or "maximum iterations" in status:
            raise budget.exceeded(solver, status)
        raise SolverError(f"{solver} found no solution ({status})")
    row_multipliers, box_multipliers = _multipliers(problem, solution, blocks)
    return QPSolution(np.asarray(solution.x, dtype=float), box_multipliers, row_multipliers)


def _solved(qp: qpsolvers.Problem, solver: str, settings: dict,
            budget: StepBudget) -> qpsolvers.Solution:
    """One ``qpsolvers.solve_problem``, OSQP bounded by what is left of the budget."""
    left = budget.remaining(solver)
    if solver == "osqp" and math.isfinite(left):  # one solve bounded by what is left
        settings = {**settings, "time_limit": left}
    try:
        return qpsolvers.solve_problem(qp, solver=solver, **settings)
    except Exception as error:  # backends raise their own types
        raise SolverError(f"{solver} raised {type(error).__name__}: {error}") from error


def _status(solution: qpsolvers.Solution) -> str:
    """"" for a solution found, else the backend's status (or why there is none)."""
    if solution.found and solution.x is not None:
        return ""
    return (str(getattr(solution.extras.get("info"), "status", ""))
            or "infeasible or not converged")


def _certified(problem: QuadraticProgram, solution: qpsolvers.Solution, blocks: list,
               settings: dict) -> bool:
    """Whether ``solution``'s KKT residual is within the backend's ``eps_abs``."""
    if solution.y is None and problem.equality_matrix is not None:
        return False
    rows, box = _multipliers(problem, solution, blocks)
    if (problem.rows is not None and rows is None) or (problem.lower is not None
                                                         and box is None):
        return False
    equalities = (np.zeros(0) if problem.equality_matrix is None
                  else np.asarray(solution.y, dtype=float))
    residual = kkt_residual(problem, np.asarray(solution.x, dtype=float), equalities,
                            np.zeros(0) if rows is None else rows, box)
    return residual <= float(settings.get("eps_abs", 0.0))


def _multipliers(problem: QuadraticProgram, solution: qpsolvers.Solution, blocks: list
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The rows' multipliers recombined from the one-sided blocks, and the box's."""
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
    return row_multipliers, box_multipliers
