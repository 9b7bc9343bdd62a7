"""The posture stage a solver cannot finish (controllers/qp/posture_stage.py): the task
stage's command stays, holding every row and the task's optimum; only the posture is
not optimised. The solvers are real: proxqp capped at one iteration fails, uncapped it
finishes, and both answers are checked against the task stage written here."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controllers.numerics import INFINITE_BOUND
from controllers.optimization.budget import StepBudget
from controllers.optimization.problem import QuadraticProgram
from controllers.optimization.proxqp import ProxQPSolver
from controllers.qp.daqp_direct import DirectDAQP
from controllers.qp.geometry import task_geometry
from controllers.qp.posture_stage import posture_stage

VARIABLES, TASK_ROWS, INEQUALITIES = 6, 2, 3


def solver(max_iter: int):
    """proxqp with its iteration caps at ``max_iter`` (outer and inner)."""
    backend = ProxQPSolver({"eps_abs": 1e-10, "eps_rel": 0.0, "max_iter": max_iter,
                            "max_iter_in": max_iter}, frozenset())
    return lambda problem: backend.solve(problem, StepBudget(None, 1e-3))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_a_posture_stage_the_solver_cannot_finish_keeps_the_task_stage_command(seed):
    rng = np.random.default_rng(seed)
    jacobian = rng.normal(size=(TASK_ROWS, VARIABLES))
    target = rng.normal(size=TASK_ROWS)
    rows = rng.normal(size=(INEQUALITIES, VARIABLES))
    rows_upper = np.full(INEQUALITIES, 0.05)
    geometry = task_geometry(jacobian, jacobian.T @ jacobian)
    task = QuadraticProgram(jacobian.T @ jacobian, -jacobian.T @ target, rows=rows,
                            rows_lower=np.full(INEQUALITIES, -INFINITE_BOUND),
                            rows_upper=rows_upper, curvature=geometry.curvature,
                            semidefinite=True)
    stage_1 = DirectDAQP({"primal_tol": 1e-10}, {}).solve(task, StepBudget(None, 1e-3))
    posture = 10.0 * rng.normal(size=VARIABLES)  # far: the posture QP has rows to meet
    capped = posture_stage(stage_1, geometry.null_basis, posture, task, jacobian, target,
                           solver(1))
    finished = posture_stage(stage_1, geometry.null_basis, posture, task, jacobian, target,
                             solver(1000))
    for qd in (capped, finished):
        assert np.all(rows @ qd <= rows_upper + 1e-9)
        np.testing.assert_allclose(jacobian @ qd, jacobian @ stage_1.x, atol=1e-8)
    # the finished posture is at least as near the posture as the task stage's command
    assert np.linalg.norm(finished - posture) <= np.linalg.norm(capped - posture) + 1e-9
