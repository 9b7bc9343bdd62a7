"""proxqp and OSQP on task stages whose optimum lies far along directions their Hessian
does not see (docs/design.md 18.7): the collision fuzz's stuck states, pinned, solved by
proxqp's last solve with ``rho`` at the stage's tolerance and by OSQP's solves with a fixed
rho, checked against daqp; and the KKT certificate those solves are taken under, against
answers written in the test."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from controllers.numerics import INFINITE_BOUND, OSQP_CAPPED_SETTINGS, SOLVER_SETTINGS
from controllers.optimization.budget import ITERATION_CAPS, BudgetExceeded, StepBudget
from controllers.optimization.kkt import kkt_residual
from controllers.optimization.problem import QuadraticProgram
from controllers.optimization.proxqp import ProxQPSolver
from controllers.qp.daqp_direct import DirectDAQP
from controllers.qp.qpsolvers_path import solve_with_qpsolvers

DATA = Path(__file__).parent / "data"


def pinned_stage() -> QuadraticProgram:
    """The task stage of the 42 failed steps of
    ``python -m tests.collision_fuzz --runs 60 --controllers qp:proxqp`` (seed 0)."""
    fields = json.loads((DATA / "proxqp-flat-task-stage.json").read_text())
    fields.pop("source")
    return QuadraticProgram(**{key: np.array(value) if isinstance(value, list) else value
                               for key, value in fields.items()})


def objective(problem: QuadraticProgram, x: np.ndarray) -> float:
    return float(0.5 * x @ problem.hessian @ x + problem.gradient @ x)


def started_budget() -> StepBudget:
    budget = StepBudget(None, 1e-3)
    budget.start()
    return budget


def test_the_pinned_stage_is_flat_and_feasible_with_room():
    """What makes it hard: five flat directions, a strictly feasible point 1 rad/s inside
    every row and joint bound (so neither infeasible nor a sliver)."""
    problem = pinned_stage()
    eigenvalues = np.linalg.eigvalsh(problem.hessian)
    assert np.sum(eigenvalues < 1e-12) == 5 and eigenvalues[5] == pytest.approx(
        problem.curvature, rel=1e-9)
    # the least-norm point of the equalities, moved nowhere else, is inside everything
    x = np.linalg.lstsq(problem.equality_matrix, problem.equality_rhs, rcond=None)[0]
    assert np.all(problem.rows @ x <= problem.rows_upper - 1e-3)
    assert np.all(np.abs(x) <= problem.upper - 1.0)


def test_the_pinned_stage_is_solved_and_agrees_with_daqp():
    problem = pinned_stage()
    solver = ProxQPSolver({**SOLVER_SETTINGS["proxqp"], **ITERATION_CAPS["proxqp"]},
                          frozenset({"eps_abs", "rho", "max_iter"}))
    answer = solver.solve(problem, started_budget())
    x = answer.x
    assert np.abs(problem.equality_matrix @ x - problem.equality_rhs).max() <= 1e-10
    assert (problem.rows @ x - problem.rows_upper).max() <= 1e-10
    tolerance = problem.tolerance()  # what the stage asks of the residuals (1e-11 here)
    assert np.all(x >= problem.lower - tolerance) and np.all(x <= problem.upper + tolerance)
    daqp = DirectDAQP({**SOLVER_SETTINGS["daqp"], **ITERATION_CAPS["daqp"]}, {})
    reference = daqp.solve(problem, started_budget()).x
    # the optimum is one value of the task's residual, not one x (flat directions)
    assert objective(problem, x) == pytest.approx(objective(problem, reference), abs=1e-10)
    difference = x - reference
    assert difference @ problem.hessian @ difference <= 1e-9


def box_problem() -> QuadraticProgram:
    """``min 1/2 |x - c|^2``, ``c = (2, 0, -1.25)``, with ``x_0 + x_1 = 1``,
    ``x_0 - x_2 <= 0.5`` and the box ``[-1, 1]^3``; its optimum is written in the tests."""
    return QuadraticProgram(np.eye(3), -np.array([2.0, 0.0, -1.25]), np.array([[1.0, 1.0, 0.0]]),
                            np.array([1.0]), np.array([[1.0, 0.0, -1.0]]),
                            np.array([-INFINITE_BOUND]), np.array([0.5]),
                            -np.ones(3), np.ones(3))


def test_the_certificate_of_an_optimum_written_in_the_test_is_zero():
    """With ``x = (0.75, 0.25, 0.25)``: the row holds at 0.5, the box holds none;
    ``x - c + y (1, 1, 0) + z (1, 0, -1) = 0`` gives ``y = -0.25``, ``z = 1.5``."""
    problem = box_problem()
    x = np.array([0.75, 0.25, 0.25])
    assert kkt_residual(problem, x, np.array([-0.25]), np.array([1.5]), np.zeros(3)) \
        == pytest.approx(0.0, abs=1e-15)


def test_the_certificate_sees_every_kind_of_miss():
    problem = box_problem()
    x, y, z = np.array([0.75, 0.25, 0.25]), np.array([-0.25]), np.array([1.5])
    # stationarity: a multiplier off by 0.1
    assert kkt_residual(problem, x, y + 0.1, z, np.zeros(3)) == pytest.approx(0.1)
    # primal: the row broken by 0.01 (the stationarity repaired along x_2)
    moved = x + np.array([0.0, 0.0, -0.01])
    assert kkt_residual(problem, moved, y, z, np.array([0.0, 0.0, 0.01])) \
        == pytest.approx(0.01)
    # complementarity: box multipliers of 1e-3 on x_0 and x_1 (0.25 and 0.75 from their
    # upper bounds), balanced by y: stationarity and the primal hold, the optimum is missed
    assert kkt_residual(problem, x, y - 1e-3, z, np.array([1e-3, 1e-3, 0.0])) \
        == pytest.approx(0.75e-3)


def test_the_certificate_sees_a_miss_beside_an_infinite_bound():
    """A row with no lower bound given as -inf, its multiplier 0: the row names no bound
    (``0 * inf`` would be NaN and numpy's max of the products NaN, which Python's max then
    passed over: the box's complementarity miss of 0.75e-3 was certified 1e-16)."""
    c = np.array([2.0, 0.0, -1.25])
    problem = QuadraticProgram(np.eye(3), -c, np.array([[1.0, 1.0, 0.0]]), np.array([1.0]),
                               np.array([[1.0, 0.0, -1.0], [0.0, 0.0, 1.0]]),
                               np.array([-np.inf, -np.inf]), np.array([0.5, 10.0]),
                               -np.ones(3), np.ones(3))
    x, y, z = np.array([0.75, 0.25, 0.25]), np.array([-0.25]), np.array([1.5, 0.0])
    assert kkt_residual(problem, x, y, z, np.zeros(3)) == pytest.approx(0.0, abs=1e-15)
    assert kkt_residual(problem, x, y - 1e-3, z, np.array([1e-3, 1e-3, 0.0])) \
        == pytest.approx(0.75e-3)
    # a multiplier naming the missing bound: nothing certified
    assert kkt_residual(problem, x, y, np.array([1.5, -1e-3]), np.array([0.0, 0.0, 1e-3])) \
        == float("inf")


@pytest.mark.parametrize("poisoned", ["x", "equalities", "rows", "box"])
def test_the_certificate_of_anything_not_finite_is_infinite(poisoned):
    """A NaN anywhere certifies nothing (numpy's max and Python's would have passed over
    it: a NaN box multiplier beside a far-from-optimal x gave 0)."""
    problem = box_problem()
    given = {"x": np.array([0.75, 0.25, 0.25]), "equalities": np.array([-0.25]),
             "rows": np.array([1.5]), "box": np.zeros(3)}
    assert kkt_residual(problem, *given.values()) == pytest.approx(0.0, abs=1e-15)
    given[poisoned] = given[poisoned].copy()
    given[poisoned][0] = np.nan
    assert kkt_residual(problem, *given.values()) == float("inf")


def test_the_pinned_stage_is_solved_within_the_default_step_budget():
    """The stage is semidefinite, so the certified flat solve comes first (0.2-0.3 ms of
    CPU), before the capped solves (the first alone about 9.5 ms, the larger cap's about
    28 ms): it is solved within the step's default budget (ten 1 ms periods of CPU), not
    only without one (with the capped solves first it failed here about 1 run in 3)."""
    problem = pinned_stage()
    solver = ProxQPSolver({**SOLVER_SETTINGS["proxqp"], **ITERATION_CAPS["proxqp"]},
                          frozenset({"eps_abs", "rho", "max_iter"}))
    budget = StepBudget("periods", 1e-3)
    budget.start()
    answer = solver.solve(problem, budget)
    daqp = DirectDAQP({**SOLVER_SETTINGS["daqp"], **ITERATION_CAPS["daqp"]}, {})
    reference = daqp.solve(problem, started_budget()).x
    assert objective(problem, answer.x) == pytest.approx(objective(problem, reference),
                                                         abs=1e-10)


def osqp_stages() -> list[QuadraticProgram]:
    """The task stages of the 403 failed steps of
    ``python -m tests.collision_fuzz --runs 60 --controllers qp:osqp`` (seed 0)."""
    stages = json.loads((DATA / "osqp-flat-task-stages.json").read_text())["stages"]
    return [QuadraticProgram(**{key: np.array(value) if isinstance(value, list) else value
                                for key, value in stage.items()}) for stage in stages]


@pytest.mark.parametrize("index", range(5))
def test_osqp_finishes_the_flat_stages_it_stalled_on_and_agrees_with_daqp(index):
    """Each stalls at OSQP's cap with the adaptive rho; the certified solves with a fixed
    one finish it, to daqp's objective within OSQP's own accuracy (eps_abs 1e-7)."""
    problem = osqp_stages()[index]
    settings = {**SOLVER_SETTINGS["osqp"], **ITERATION_CAPS["osqp"]}
    with pytest.raises(BudgetExceeded, match="maximum iterations"):
        solve_with_qpsolvers(problem, "osqp", settings, started_budget())
    x = solve_with_qpsolvers(problem, "osqp", settings, started_budget(),
                             OSQP_CAPPED_SETTINGS).x
    assert np.abs(problem.equality_matrix @ x - problem.equality_rhs).max() <= 1e-7
    assert (problem.rows @ x - problem.rows_upper).max() <= 1e-7
    assert np.all(x >= problem.lower - 1e-7) and np.all(x <= problem.upper + 1e-7)
    daqp = DirectDAQP({**SOLVER_SETTINGS["daqp"], **ITERATION_CAPS["daqp"]}, {})
    reference = daqp.solve(problem, started_budget()).x
    assert objective(problem, x) == pytest.approx(objective(problem, reference), abs=1e-7)
