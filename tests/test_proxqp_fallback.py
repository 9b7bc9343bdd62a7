"""proxqp's last solve of a stage still at its caps (docs/design.md 18.7): a fresh object
with ten times the outer cap, whose answer meets the tolerances of any, checked against an
independent high-accuracy proxsuite solve of the same problem."""

from __future__ import annotations

import numpy as np
import proxsuite
import pytest

from controllers.base import SolverError
from controllers.numerics import PROXQP_FALLBACK_ITERATIONS, SOLVER_SETTINGS
from controllers.optimization.budget import BudgetExceeded, StepBudget
from controllers.optimization.problem import QuadraticProgram
from controllers.optimization.proxqp import ProxQPSolver


def semidefinite_problem(seed: int) -> QuadraticProgram:
    """A task-stage-like QP: ``H = M^T M`` of rank 4 on 6 variables, one equality, four
    rows binding near a feasible point, the box."""
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(4, 6))
    point = rng.uniform(-0.5, 0.5, 6)
    A, C = rng.normal(size=(1, 6)), rng.normal(size=(4, 6))
    return QuadraticProgram(M.T @ M, rng.normal(size=6), A, A @ point, C, np.full(4, -1e20),
                            C @ point + 0.01, -np.ones(6), np.ones(6),
                            curvature=float(np.linalg.eigvalsh(M @ M.T).min()),
                            semidefinite=True)


def direct(problem: QuadraticProgram, max_iter: int, eps_abs: float):
    """proxsuite's dense QP on ``problem``, one solve at ``max_iter`` outer iterations."""
    qp = proxsuite.proxqp.dense.QP(6, 1, 4, box_constraints=True)
    qp.settings.eps_abs, qp.settings.eps_rel = eps_abs, 0.0
    qp.settings.max_iter, qp.settings.max_iter_in = max_iter, 1000
    qp.init(problem.hessian, problem.gradient, problem.equality_matrix, problem.equality_rhs,
            problem.rows, problem.rows_lower, problem.rows_upper, problem.lower, problem.upper)
    qp.solve()
    return qp.results


def solver(max_iter: int, users: bool = False) -> ProxQPSolver:
    """The controller's proxqp with an outer cap of ``max_iter``: the project's (the last
    solve may exceed it), or the user's (``users``: never exceeded)."""
    return ProxQPSolver({**SOLVER_SETTINGS["proxqp"], "max_iter": max_iter, "max_iter_in": 50},
                        frozenset({"eps_abs", "rho", *(() if users else ("max_iter",))}))


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_a_stage_at_its_caps_is_solved_on_a_fresh_object_with_more(seed):
    problem = semidefinite_problem(seed)
    reference = direct(problem, 10_000, 1e-13)
    assert reference.info.status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
    needed = reference.info.iter_ext
    cap = max(1, (needed - 1) // 2)  # too few for one solve, enough times ten
    assert cap * PROXQP_FALLBACK_ITERATIONS >= needed
    capped = direct(problem, cap, problem.tolerance())
    assert capped.info.status == proxsuite.proxqp.QPSolverOutput.PROXQP_MAX_ITER_REACHED
    budget = StepBudget(None, 1e-3)
    budget.start()
    answer = solver(cap).solve(problem, budget)
    np.testing.assert_allclose(answer.x, reference.x, rtol=0.0, atol=1e-8)
    assert abs(problem.equality_matrix @ answer.x - problem.equality_rhs).max() <= 1e-10
    assert (problem.rows @ answer.x - problem.rows_upper).max() <= 1e-10


def test_a_stage_out_of_iterations_after_the_last_solve_still_fails():
    """With no outer iteration to spare even ten times over (a cap of 0 iterations does
    nothing), the step fails as before, naming the cap."""
    problem = semidefinite_problem(3)
    budget = StepBudget(None, 1e-3)
    budget.start()
    with pytest.raises(BudgetExceeded, match=r"iteration limit \(0 x 50"):
        solver(0).solve(problem, budget)
    assert issubclass(BudgetExceeded, SolverError)


def test_a_cap_the_user_set_is_never_exceeded():
    """The problem the first test solves past its cap, with that cap the user's: the step
    fails at it, naming it (tests/test_errors.py: one iteration asked, nothing found)."""
    problem = semidefinite_problem(3)
    reference = direct(problem, 10_000, 1e-13)
    cap = max(1, (reference.info.iter_ext - 1) // 2)
    budget = StepBudget(None, 1e-3)
    budget.start()
    with pytest.raises(BudgetExceeded, match=rf"iteration limit \({cap} x 50"):
        solver(cap, users=True).solve(problem, budget)

