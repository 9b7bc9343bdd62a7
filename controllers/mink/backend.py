"""mink's QP and the least-residual QP, solved with one backend within the step's budget
(docs/design.md 10.5-10.7)."""

from __future__ import annotations

from typing import Any, Sequence

import mink
import numpy as np
import qpsolvers

from ..base import SolverError
from ..numerics import (DAQP_PROXIMAL_FLOOR, DAQP_PROXIMAL_WEIGHT, INFINITE_BOUND, PROXQP_RHO,
                        SOLVER_SETTINGS, TASK_ACCURACY)
from ..optimization.budget import ITERATION_CAPS, StepBudget
from ..optimization.least_residual import LeastResidualProblem
from ..optimization.problem import QuadraticProgram
from ..optimization.proxqp import ProxQPSolver
from .acceleration_limit import AccelerationLimit
from .joint_box import JointBoxLimit
from .settings import FIXED_SETTINGS, MINK_ITERATION_CAPS, VELOCITY_TOLERANCES


class MinkBackend:
    """The backend ``solver`` with the peer's settings: ``VELOCITY_TOLERANCES`` times
    ``dt``, ``FIXED_SETTINGS``, ``MINK_ITERATION_CAPS``, then ``solver_settings``.

    proxqp runs on the shared proxsuite objects (:class:`ProxQPSolver`), which cap its
    inner iterations too, unless a setting is one they cannot apply (then qpsolvers). Its
    ``rho`` follows the posture's curvature ``c^2`` (``PROXQP_RHO c^2``) unless the user
    set it. The least-residual stage takes the QP controller's settings
    (``SOLVER_SETTINGS``, in velocity units) with the caps the user set.
    """

    def __init__(self, solver: str, dt: float, posture_cost: float,
                 solver_settings: dict | None, budget: StepBudget) -> None:
        self.solver = solver
        self.dt = dt
        self.budget = budget
        self.settings: dict[str, Any] = {key: value * dt
                         for key, value in VELOCITY_TOLERANCES.get(solver, {}).items()}
        self.settings.update(FIXED_SETTINGS.get(solver, {}))
        self.settings.update(MINK_ITERATION_CAPS.get(solver, {}))
        self.settings.update(solver_settings or {})
        #: iteration caps the user set: the least-residual solve takes them too
        self._user_caps = {k: v for k, v in (solver_settings or {}).items()
                           if k in ITERATION_CAPS.get(solver, {})}
        #: proxqp's rho follows the posture cost, unless the user set it
        self._proxqp_rho_tuned = (solver == "proxqp" and posture_cost > 0.0
                                  and "rho" not in (solver_settings or {}))
        self._proxqp = self._least_residual_proxqp = None
        if solver == "proxqp" and ProxQPSolver.accepts(self.settings):
            ours = frozenset(() if "max_iter" in self._user_caps else ("max_iter",))
            self._proxqp = ProxQPSolver(self.settings, ours | frozenset(
                {"rho"} if self._proxqp_rho_tuned else ()))
            self._least_residual_proxqp = ProxQPSolver(
                {**SOLVER_SETTINGS["proxqp"], **ITERATION_CAPS["proxqp"], **self._user_caps},
                ours | {"eps_abs", "rho"})
        self._posture_curvature = 1.0  # c^2, the curvature the posture task gives mink's QP

    def set_posture_cost(self, cost: float) -> None:
        """The posture task's cost ``c`` of this step (its curvature ``c^2`` sets proxqp's
        ``rho``)."""
        self._posture_curvature = cost**2
        if self._proxqp_rho_tuned and self._proxqp is None:
            self.settings["rho"] = PROXQP_RHO * cost**2

    def solve_ik(self, configuration: mink.Configuration, tasks: Sequence[mink.Task],
                 damping: float, limits: list[mink.Limit], constraints: Sequence[mink.Task],
                 variable_bounds: Sequence[JointBoxLimit | AccelerationLimit]) -> np.ndarray:
        """``mink.build_ik`` solved within the step's budget (``solve_ik``'s two lines, so
        that a budget spent is told from an infeasible problem): MuJoCo's velocity ``v``.
        ``variable_bounds`` (the joint box, the acceleration box) bound the variable of
        their 1-dof joints, intersected."""
        self.budget.remaining(self.solver)
        try:
            problem = mink.build_ik(configuration, tasks, self.dt, damping, limits, constraints)
            if variable_bounds:
                lb = np.full(configuration.nv, -INFINITE_BOUND)
                ub = np.full(configuration.nv, INFINITE_BOUND)
                for limit in variable_bounds:
                    lower, upper = limit.displacement_bounds(configuration, self.dt)
                    np.maximum(lb, lower, out=lb)
                    np.minimum(ub, upper, out=ub)
                problem.lb, problem.ub = lb, ub
            if self._proxqp is not None:
                return self._solve_proxqp(problem) / self.dt
            solution = qpsolvers.solve_problem(problem, solver=self.solver, **self.settings)
        except SolverError:
            raise
        except Exception as error:  # backend errors
            raise SolverError(f"mink with solver {self.solver!r} raised "
                              f"{type(error).__name__}: {error}") from error
        if not solution.found or solution.x is None:
            status = str(getattr(solution.extras.get("info"), "status", ""))
            if ("time limit" in status or "maximum iterations" in status
                    or "MAX_ITER" in status):
                raise self.budget.exceeded(f"mink:{self.solver}", status)
            raise SolverError(f"mink with solver {self.solver!r} found no solution "
                              f"({status or 'infeasible, or out of iterations'})")
        return solution.x / self.dt

    def _solve_proxqp(self, problem: qpsolvers.Problem) -> np.ndarray:
        """mink's QP ``min 1/2 dq'P dq + q'dq  s.t.  G dq <= h,  A dq = b`` by a fresh
        capped proxsuite solve (as ``qpsolvers``' proxqp path: no state carried between
        steps), ``rho`` from the posture's curvature ``c^2``."""
        P, q, G, h, A, b, lb, ub = problem.unpack()
        self._proxqp.reset()
        try:
            return self._proxqp.solve(QuadraticProgram(
                np.asarray(P, dtype=float), q, A, b, G,
                None if G is None else np.full(G.shape[0], -INFINITE_BOUND), h, lb, ub,
                curvature=self._posture_curvature), self.budget).x
        except SolverError as error:  # the same type, naming mink
            raise type(error)(f"mink:{error}") from error

    def least_residual(self, problem: LeastResidualProblem) -> np.ndarray:
        """The least-residual QP's solution ``x = [qd; t]`` (velocity units)."""
        if self._least_residual_proxqp is not None:
            self._least_residual_proxqp.reset()
            return self._least_residual_proxqp.solve(QuadraticProgram(
                problem.hessian, problem.gradient, rows=problem.rows,
                rows_lower=problem.rows_lower, rows_upper=problem.rows_upper,
                lower=problem.lower, upper=problem.upper, curvature=problem.curvature,
                semidefinite=problem.semidefinite), self.budget).x
        settings = {**SOLVER_SETTINGS.get(self.solver, {}), **ITERATION_CAPS.get(self.solver, {}),
                    **self._user_caps}
        self.budget.remaining(self.solver)
        if self.solver == "daqp" and problem.semidefinite:  # as the QP controller's
            settings.update(eps_prox=DAQP_PROXIMAL_WEIGHT, eta_prox=max(
                TASK_ACCURACY * problem.curvature, DAQP_PROXIMAL_FLOOR))
        qp = qpsolvers.Problem(problem.hessian, problem.gradient, problem.rows,
                               problem.rows_upper, lb=problem.lower, ub=problem.upper)
        try:
            solution = qpsolvers.solve_problem(qp, solver=self.solver, **settings)
        except Exception as error:  # backends raise their own types
            raise SolverError(f"{self.solver} raised {type(error).__name__}: {error}") from error
        if not solution.found or solution.x is None:
            raise SolverError(f"{self.solver} found no least-residual solution")
        return solution.x
