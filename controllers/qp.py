"""Whole-body differential-IK QP holding the same constraint rows (docs/design.md section 4)."""

from __future__ import annotations

import math
from typing import Iterable

import numpy as np
import qpsolvers
import scipy.sparse

from constraints import Constraint
from constraints.validation import as_number, as_vector

from .base import Controller, Kinematics, SolverError
from .joint_limits import DEFAULT_LIMIT_GAIN

#: Backends that take sparse matrices (given dense ones, qpsolvers converts and warns).
SPARSE_SOLVERS = frozenset({"osqp", "scs", "clarabel", "highs", "piqp", "qpalm"})

#: Tolerances per backend, chosen so that proxqp and daqp hold the equality rows to
#: 1e-9 m/s or better. OSQP (first order, ADMM) is asked for 1e-7 with polishing and
#: usually lands between 1e-7 and 1e-9: its residuals are reported, not hidden.
SOLVER_SETTINGS: dict[str, dict] = {
    "proxqp": {"eps_abs": 1e-10, "eps_rel": 0.0, "max_iter": 1000},  # fails fast, not in 10^4 iterations
    "daqp": {"primal_tol": 1e-10},
    "osqp": {"eps_abs": 1e-7, "eps_rel": 0.0, "polishing": True, "max_iter": 20000},
}

_ONES = [1.0] * 6

#: What stands for an infinite joint bound in the backends' box constraints.
INFINITE_BOUND = 1e20

#: proxqp settings that are arguments of ``init`` rather than fields of ``settings``.
_PROXQP_INIT_ARGUMENTS = frozenset({"rho", "mu_eq", "mu_in", "compute_preconditioner",
                                    "manual_minimal_H_eigenvalue"})


def _daqp_accepts(settings: dict) -> bool:
    """Whether every key is a daqp setting ``daqp.solve`` takes (else: qpsolvers)."""
    import daqp  # noqa: PLC0415 - only when daqp is the backend

    return all(k in daqp.Model().settings for k in settings)


class _ProxQP:
    """A persistent ``proxsuite.proxqp.dense.QP``: ``init`` once, ``update`` + ``solve`` after.

    The joint bounds go in proxsuite's box constraints, the barrier rows in ``C``. The
    object is rebuilt when the number of equality or inequality rows changes (and after
    a failed solve, so that a bad state never carries over). ``update`` keeps the
    preconditioner of ``init``: recomputing it every step cost more than it saved, and
    the stopping test is on the unscaled residuals, so the tolerances hold either way.

    ``initial_guess`` (a ``proxsuite.proxqp.InitialGuess`` name, in ``solver_settings``)
    defaults to ``EQUALITY_CONSTRAINED_INITIAL_GUESS``, which is what a fresh proxqp
    solve uses: measured on the built-in robots it needs no more iterations than
    ``WARM_START_WITH_PREVIOUS_RESULT`` (2 per step on a smooth closed loop, for both),
    and warm starting from the previous result now and then stopped at a spurious
    ``PROXQP_PRIMAL_INFEASIBLE`` on independent configurations. With a warm start
    chosen, a step that does not reach ``PROXQP_SOLVED`` is solved again from the
    equality-constrained guess before it is reported as a failure.
    """

    def __init__(self, nv: int, settings: dict) -> None:
        import proxsuite  # noqa: PLC0415 - only when proxqp is the backend

        self._proxqp = proxsuite.proxqp
        self.nv = nv
        self.init_arguments = {k: v for k, v in settings.items() if k in _PROXQP_INIT_ARGUMENTS}
        self.settings = {k: v for k, v in settings.items() if k not in _PROXQP_INIT_ARGUMENTS}
        guess = self.settings.pop("initial_guess", "EQUALITY_CONSTRAINED_INITIAL_GUESS")
        if isinstance(guess, str):
            if guess not in proxsuite.proxqp.InitialGuess.__members__:
                raise ValueError(f"unknown proxqp initial_guess {guess!r}; one of "
                                 f"{list(proxsuite.proxqp.InitialGuess.__members__)}")
            guess = proxsuite.proxqp.InitialGuess.__members__[guess]
        self.initial_guess = guess
        self.fallback_guess = proxsuite.proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
        self.solved = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
        self.qp = None
        self.shape: tuple[int, int, bool] | None = None

    @staticmethod
    def accepts(settings: dict) -> bool:
        """Whether every key is a proxqp setting this class can apply (else: qpsolvers)."""
        import proxsuite  # noqa: PLC0415

        fields = set(dir(proxsuite.proxqp.dense.QP(1, 0, 0).settings))
        return all(k in fields or k in _PROXQP_INIT_ARGUMENTS for k in settings)

    def reset(self) -> None:
        self.qp, self.shape = None, None

    def solve(self, H, g, A, b, C, u, lower, upper) -> np.ndarray:
        """``x`` of ``min 1/2 x'Hx + g'x, A x = b, C x <= u, lower <= x <= upper``."""
        boxed = lower is not None
        shape = (0 if A is None else A.shape[0], 0 if C is None else C.shape[0], boxed)
        l = None if C is None else np.full(C.shape[0], -np.inf)
        if self.qp is None or shape != self.shape:
            qp = self._proxqp.dense.QP(self.nv, shape[0], shape[1], box_constraints=boxed)
            for key, value in self.settings.items():
                setattr(qp.settings, key, value)
            qp.settings.initial_guess = self.initial_guess
            qp.init(H, g, A, b, C, l, u, lower, upper, **self.init_arguments)
            self.qp, self.shape = qp, shape
        else:
            qp = self.qp
            qp.update(H, g, A, b, C, l, u, lower, upper)
        qp.solve()
        status = qp.results.info.status
        if status != self.solved and self.initial_guess != self.fallback_guess:
            qp.settings.initial_guess = self.fallback_guess
            qp.solve()
            qp.settings.initial_guess = self.initial_guess
            status = qp.results.info.status
        if status != self.solved:
            self.reset()
            raise SolverError(f"proxqp found no solution ({status.name})")
        return qp.results.x.copy()


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
    robot, constraints, dt, limit_gain, position_limits, velocity_limits, strict : see
        :class:`controllers.base.Controller`.
    solver : a ``qpsolvers`` backend: ``"proxqp"`` (default), ``"daqp"``, ``"osqp"``, ...
        proxqp runs as one persistent ``proxsuite`` dense QP (``init`` once, then
        ``update`` + ``solve``; see ``_ProxQP``), daqp through ``daqp.solve`` directly, the
        others through ``qpsolvers``. ``solver_settings`` the direct calls cannot apply
        (a key that is no proxqp/daqp setting) send proxqp/daqp through ``qpsolvers`` too.
    mu : Tikhonov regularisation of ``qd`` (keeps the Hessian positive definite).
    twist_weight : (6,) diagonal weight ``W`` of the twist error (default identity).
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
        limit_gain: float = DEFAULT_LIMIT_GAIN,
        position_limits: bool = True,
        velocity_limits: bool = True,
        solver_settings: dict | None = None,
        strict: bool = False,
    ) -> None:
        super().__init__(robot, dt=dt, limit_gain=limit_gain, position_limits=position_limits,
                         velocity_limits=velocity_limits, strict=strict)
        if solver not in qpsolvers.available_solvers:
            raise ValueError(
                f"QP solver {solver!r} is not available; installed: {qpsolvers.available_solvers}"
            )
        self.solver = solver
        self.mu = as_number(mu, "mu", 0.0)
        self.settings = dict(SOLVER_SETTINGS.get(solver, {}))
        self.settings.update(solver_settings or {})
        weight = np.ones(6) if twist_weight is None else as_vector(twist_weight, 6, "twist_weight")
        if np.any(weight < 0):
            raise ValueError(f"twist_weight must be non-negative, got {weight}")
        self.twist_weight = weight
        # proxqp and daqp are called directly (a persistent proxqp object; daqp.solve),
        # the other backends through qpsolvers. Settings a direct call cannot apply send
        # proxqp back through qpsolvers as well.
        self._proxqp = (_ProxQP(self.model.nv, self.settings)
                        if solver == "proxqp" and _ProxQP.accepts(self.settings) else None)
        self._direct_daqp = solver == "daqp" and _daqp_accepts(self.settings)
        if self._direct_daqp:
            import daqp  # noqa: PLC0415 - only when daqp is the backend

            self._daqp = daqp
        self._daqp_shape: tuple[int, int, int] | None = None
        self._mu_used, self._mu_eye = None, None
        self.set_constraints(constraints)

    def _prepare(self) -> None:
        self._equalities = [i for i, k in enumerate(self.constraints) if k.is_equality]
        self._barriers = [i for i, k in enumerate(self.constraints) if not k.is_equality]
        if self._proxqp is not None:
            self._proxqp.reset()

    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        J = kinematics.ee_jacobian
        unit_weight = self.twist_weight.tolist() == _ONES
        weighted = J.T if unit_weight else J.T * self.twist_weight
        P = np.dot(weighted, J)
        mu = self.mu
        if mu != self._mu_used:  # mu I, rebuilt only when mu changes
            self._mu_used, self._mu_eye = mu, mu * np.eye(self.model.nv)
        P += self._mu_eye
        c = np.dot(twist, J) if unit_weight else np.dot(weighted, twist)
        np.negative(c, out=c)
        equalities, barriers = self._equalities, self._barriers
        A, b = self.constraint_rows(equalities) if equalities else (None, None)
        G, h = None, None
        if barriers:
            A_b, b_b = self.constraint_rows(barriers)
            G, h = -A_b, -b_b
        lb, ub = self.joint_bounds.box(kinematics.q)
        if not (math.isfinite(sum(lb.tolist())) and math.isfinite(sum(ub.tolist()))):
            if not (np.isfinite(lb).any() or np.isfinite(ub).any()):
                lb = ub = None  # nothing bounded
            else:
                lb = np.where(np.isfinite(lb), lb, -INFINITE_BOUND)
                ub = np.where(np.isfinite(ub), ub, INFINITE_BOUND)
        self.info.method = f"qp:{self.solver}"
        if self._proxqp is not None:
            qd = self._proxqp.solve(P, c, A, b, G, h, lb, ub)
        elif self._direct_daqp:
            qd = self._solve_daqp(P, c, A, b, G, h, lb, ub)
        else:
            qd = self._solve_qpsolvers(P, c, A, b, G, h, lb, ub)
        if A is not None:
            self.info.equality_residual = max(map(abs, (np.dot(A, qd) - b).tolist()))
        if G is not None:
            self.info.active_barriers = tuple(
                barriers[i] for i in np.flatnonzero(G @ qd - h > -1e-9))
        self._report_twist_error(J, qd, twist)
        return qd

    def _solve_daqp(self, P, c, A, b, G, h, lb, ub) -> np.ndarray:
        """``daqp.solve`` directly (what qpsolvers does, without its ``Problem`` layer).

        Rows: the joint bounds first (daqp's simple bounds), then the barrier
        inequalities, then the equalities (``sense`` 5). ``daqp.Model`` (a persistent
        workspace that keeps the active set) was measured too: about 1 us slower per step
        here, on independent and on smooth sequences alike.
        """
        nv = self.model.nv
        n_box = 0 if lb is None else nv
        n_in = 0 if G is None else G.shape[0]
        n_eq = 0 if A is None else A.shape[0]
        shape = (n_box, n_in, n_eq)
        if self._daqp_shape != shape:  # bound vectors and constraint types, per shape
            upper, lower = np.empty(n_box + n_in + n_eq), np.empty(n_box + n_in + n_eq)
            lower[n_box:n_box + n_in] = -1e30
            sense = np.zeros(upper.size, dtype=np.intc)
            sense[n_box + n_in:] = 5
            self._daqp_shape, self._daqp_buffers = shape, (upper, lower, sense)
        upper, lower, sense = self._daqp_buffers
        if n_box:
            upper[:n_box], lower[:n_box] = ub, lb
        if n_in:
            upper[n_box:n_box + n_in] = h
        if n_eq:
            upper[n_box + n_in:] = b
            lower[n_box + n_in:] = b
        rows = A if G is None else (G if A is None else np.vstack([G, A]))
        if rows is None:
            rows = np.zeros((0, nv))
        try:
            x, _, exitflag, _ = self._daqp.solve(P, c, rows, upper, lower, sense, **self.settings)
        except Exception as error:  # the backend raises its own types
            raise SolverError(f"daqp raised {type(error).__name__}: {error}") from error
        if exitflag <= 0:
            raise SolverError(f"daqp found no solution (exit flag {exitflag})")
        return x

    def _solve_qpsolvers(self, P, c, A, b, G, h, lb, ub) -> np.ndarray:
        if self.solver in SPARSE_SOLVERS:
            P = scipy.sparse.csc_matrix(P)
            A = None if A is None else scipy.sparse.csc_matrix(A)
            G = None if G is None else scipy.sparse.csc_matrix(G)
        problem = qpsolvers.Problem(P, c, G, h, A, b, lb=lb, ub=ub)
        try:
            solution = qpsolvers.solve_problem(problem, solver=self.solver, **self.settings)
        except Exception as error:  # backends raise their own types
            raise SolverError(f"{self.solver} raised {type(error).__name__}: {error}") from error
        if not solution.found or solution.x is None:
            raise SolverError(f"{self.solver} found no solution (infeasible or not converged)")
        return np.asarray(solution.x, dtype=float)
