"""daqp called directly: ``daqp.solve`` without qpsolvers' ``Problem`` layer."""

from __future__ import annotations

import numpy as np

from ..base import SolverError
from ..numerics import (DAQP_PROXIMAL_FLOOR, DAQP_PROXIMAL_WEIGHT, DAQP_ZERO_FRACTION,
                        TASK_ACCURACY, TOLERANCE_RANGE)
from ..optimization.budget import DAQP_OUT_OF_BUDGET, StepBudget
from ..optimization.problem import QPSolution, QuadraticProgram

#: ``sense`` of an equality row in daqp.
_EQUALITY = 5


class DirectDAQP:
    """``daqp.solve`` on a :class:`QuadraticProgram`, with buffers kept per problem shape.

    Rows: the joint bounds first (daqp's simple bounds), then the inequality rows, then
    the equalities (``sense`` 5). A semidefinite problem is solved by daqp's proximal-point
    iterations (``DAQP_PROXIMAL_WEIGHT``, ``eta_prox`` from the curvature, ``zero_tol``
    below ``eta_prox``) unless the user set those settings. A persistent ``daqp.Model``
    (which keeps the active set) is no faster per step here (docs/design.md 10.2).

    ``settings`` is the controller's own dict (read at every solve); ``user_settings`` the
    keys the user gave.
    """

    def __init__(self, settings: dict, user_settings: dict) -> None:
        import daqp  # noqa: PLC0415 - only when daqp is the backend

        self._daqp = daqp
        self.settings = settings
        #: the proximal settings of a semidefinite stage the user did not set
        self.proximal_keys = {"eps_prox", "eta_prox", "zero_tol"} - set(user_settings)
        self._buffers: dict[tuple[int, int, int], tuple[np.ndarray, ...]] = {}

    @staticmethod
    def accepts(settings: dict) -> bool:
        """Whether every key is a daqp setting ``daqp.solve`` takes (else: qpsolvers)."""
        import daqp  # noqa: PLC0415 - only when daqp is the backend

        return all(k in daqp.Model().settings for k in settings)

    def solve(self, problem: QuadraticProgram, budget: StepBudget) -> QPSolution:
        variables, n_eq, n_rows, boxed = problem.shape
        n_box = variables if boxed else 0
        shape = (n_box, n_rows, n_eq)
        buffers = self._buffers.get(shape)
        if buffers is None:  # bound vectors and constraint types, per shape
            sense = np.zeros(n_box + n_rows + n_eq, dtype=np.intc)
            sense[n_box + n_rows:] = _EQUALITY
            buffers = (np.empty(sense.size), np.empty(sense.size), sense)
            self._buffers[shape] = buffers
        upper, lower, sense = buffers
        if boxed:
            upper[:n_box], lower[:n_box] = problem.upper, problem.lower
        if n_rows:
            upper[n_box:n_box + n_rows] = problem.rows_upper
            lower[n_box:n_box + n_rows] = problem.rows_lower
        if n_eq:
            upper[n_box + n_rows:] = lower[n_box + n_rows:] = problem.equality_rhs
        rows = problem.equality_matrix if problem.rows is None else (
            problem.rows if problem.equality_matrix is None
            else np.vstack([problem.rows, problem.equality_matrix]))
        if rows is None:
            rows = np.zeros((0, variables))
        budget.remaining("daqp")
        settings = self.settings
        if problem.semidefinite and self.proximal_keys:
            eta = min(max(TASK_ACCURACY * problem.curvature, DAQP_PROXIMAL_FLOOR),
                      TOLERANCE_RANGE[1])
            proximal = {"eps_prox": DAQP_PROXIMAL_WEIGHT, "eta_prox": eta,
                        "zero_tol": DAQP_ZERO_FRACTION * eta}
            settings = {**settings, **{k: proximal[k] for k in self.proximal_keys}}
        try:
            x, _, exitflag, info = self._daqp.solve(problem.hessian, problem.gradient, rows, upper,
                                                    lower, sense, **settings)
        except Exception as error:  # the backend raises its own types
            raise SolverError(f"daqp raised {type(error).__name__}: {error}") from error
        if exitflag in DAQP_OUT_OF_BUDGET:
            raise budget.exceeded("daqp", DAQP_OUT_OF_BUDGET[exitflag])
        if exitflag <= 0:
            raise SolverError(f"daqp found no solution (exit flag {exitflag})")
        multipliers = info["lam"]
        return QPSolution(x, multipliers[:n_box] if boxed else None,
                          multipliers[n_box:n_box + n_rows] if n_rows else None)
