"""Whole-body differential-IK QP holding the same constraint rows (DESIGN.md section 4)."""

from __future__ import annotations

from typing import Iterable

import numpy as np
import qpsolvers
import scipy.sparse


from constraints import Constraint

from .base import Controller, Kinematics, SolverError

#: Backends that take sparse matrices (given dense ones, qpsolvers converts and warns).
SPARSE_SOLVERS = frozenset({"osqp", "scs", "clarabel", "highs", "piqp", "qpalm"})

#: Tolerances per backend, chosen so that proxqp and daqp hold the equality rows to
#: 1e-9 m/s or better. OSQP (first order, ADMM) is asked for 1e-7 with polishing and
#: usually lands between 1e-7 and 1e-9: its residuals are reported, not hidden.
SOLVER_SETTINGS: dict[str, dict] = {
    "proxqp": {"eps_abs": 1e-10, "eps_rel": 0.0},
    "daqp": {"primal_tol": 1e-10},
    "osqp": {"eps_abs": 1e-7, "eps_rel": 0.0, "polishing": True, "max_iter": 20000},
}


class QPController(Controller):
    """``min 1/2 |J_e qd - V_e|_W^2 + 1/2 mu |qd|^2`` under the constraints and limits.

    ::

        s.t.  A qd = b                                 equality rows, same drift as the CJM
              G qd <= h                                barrier rows: -n.v_c <= K d - n.v_plane
              max(-qd_max, g (q_min - q)/dt) <= qd <= min(qd_max, g (q_max - q)/dt)

    With no inequality active and ``mu -> 0`` the solution equals the CJM's whenever it
    is unique (the core equivalence test).

    Parameters
    ----------
    robot, constraints, strict : see :class:`controllers.base.Controller`.
    solver : a ``qpsolvers`` backend: ``"proxqp"`` (default), ``"daqp"``, ``"osqp"``, ...
    dt : control period (s) that scales the position limits.
    mu : Tikhonov regularisation of ``qd`` (keeps the Hessian positive definite).
    twist_weight : (6,) diagonal weight ``W`` of the twist error (default identity).
    limit_gain : fraction ``g`` of the distance to a position limit allowed per step.
    solver_settings : extra keyword arguments for the backend (override the defaults).
    """

    def __init__(
        self,
        robot,
        constraints: Iterable[Constraint] = (),
        solver: str = "proxqp",
        dt: float = 1e-3,
        mu: float = 1e-10,
        twist_weight=None,
        limit_gain: float = 0.95,
        position_limits: bool = True,
        velocity_limits: bool = True,
        solver_settings: dict | None = None,
        strict: bool = False,
    ) -> None:
        if solver not in qpsolvers.available_solvers:
            raise ValueError(
                f"QP solver {solver!r} is not available; installed: {qpsolvers.available_solvers}"
            )
        for name, value in (("dt", dt), ("limit_gain", limit_gain)):
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if not np.isfinite(mu) or mu < 0:
            raise ValueError(f"mu must be finite and >= 0, got {mu}")
        self.solver = solver
        self.dt = float(dt)
        self.mu = float(mu)
        self.limit_gain = float(limit_gain)
        self.position_limits = bool(position_limits)
        self.velocity_limits = bool(velocity_limits)
        self.settings = dict(SOLVER_SETTINGS.get(solver, {}))
        self.settings.update(solver_settings or {})
        super().__init__(robot, constraints, strict=strict)
        weight = np.ones(6) if twist_weight is None else np.asarray(twist_weight, dtype=float)
        if weight.shape != (6,) or not np.all(np.isfinite(weight)) or np.any(weight < 0):
            raise ValueError(f"twist_weight must be 6 finite non-negative numbers, got {weight}")
        self.twist_weight = weight
        self._revolute = self._scalar_joint_indices()

    def _scalar_joint_indices(self) -> tuple[np.ndarray, np.ndarray]:
        """(q index, v index) of the joints whose position limits apply as ``q + qd dt``."""
        model = self.model
        qi, vi = [], []
        for j in range(1, model.njoints):
            if model.nqs[j] == 1 and model.nvs[j] == 1:
                qi.append(model.idx_qs[j])
                vi.append(model.idx_vs[j])
        return np.array(qi, dtype=int), np.array(vi, dtype=int)

    def bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Box ``lb <= qd <= ub`` from the velocity and (scaled) position limits."""
        nv = self.model.nv
        lower, upper = np.full(nv, -np.inf), np.full(nv, np.inf)
        if self.velocity_limits:
            lower, upper = -self.velocity_limit.copy(), self.velocity_limit.copy()
        if self.position_limits:
            qi, vi = self._revolute
            q_min = self.model.lowerPositionLimit[qi]
            q_max = self.model.upperPositionLimit[qi]
            finite = np.isfinite(q_min) & np.isfinite(q_max) & (q_max > q_min)
            scale = self.limit_gain / self.dt
            lower[vi[finite]] = np.maximum(lower[vi[finite]], scale * (q_min - q[qi])[finite])
            upper[vi[finite]] = np.minimum(upper[vi[finite]], scale * (q_max - q[qi])[finite])
        upper = np.maximum(upper, lower)  # a joint already past a limit may only come back
        return lower, upper

    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        J = kinematics.ee_jacobian
        weighted = J.T * self.twist_weight
        P = weighted @ J + self.mu * np.eye(self.model.nv)
        c = -weighted @ twist
        equalities = [i for i, k in enumerate(self.constraints) if k.is_equality]
        barriers = [i for i, k in enumerate(self.constraints) if not k.is_equality]
        A, b = self.constraint_rows(equalities) if equalities else (None, None)
        G, h = None, None
        if barriers:
            A_b, b_b = self.constraint_rows(barriers)
            G, h = -A_b, -b_b
        lb, ub = self.bounds(kinematics.q)
        bounded = np.isfinite(lb) | np.isfinite(ub)
        if self.solver in SPARSE_SOLVERS:
            P = scipy.sparse.csc_matrix(P)
            A_qp = None if A is None else scipy.sparse.csc_matrix(A)
            G_qp = None if G is None else scipy.sparse.csc_matrix(G)
        else:
            A_qp, G_qp = A, G
        problem = qpsolvers.Problem(
            P, c, G_qp, h, A_qp, b,
            lb=np.where(np.isfinite(lb), lb, -1e20) if bounded.any() else None,
            ub=np.where(np.isfinite(ub), ub, 1e20) if bounded.any() else None,
        )
        self.info.method = f"qp:{self.solver}"
        try:
            solution = qpsolvers.solve_problem(problem, solver=self.solver, **self.settings)
        except Exception as error:  # backends raise their own types
            raise SolverError(f"{self.solver} raised {type(error).__name__}: {error}") from error
        if not solution.found or solution.x is None:
            raise SolverError(f"{self.solver} found no solution (infeasible or not converged)")
        qd = np.asarray(solution.x, dtype=float)
        if A is not None:
            self.info.equality_residual = float(np.max(np.abs(A @ qd - b)))
        if G is not None:
            self.info.active_barriers = tuple(
                barriers[i] for i in np.flatnonzero(G @ qd - h > -1e-9))
        return qd
