"""Whole-body differential-IK QP with the CJM's priorities (docs/design.md sections 4.7, 10).

The default is the lexicographic solve of section 10: the constraint rows hard, then the
EE twist in the least-squares sense, then the posture, each stage a quadratic program
for the chosen backend::

    stage 1 (task):     qd_1 = argmin 1/2 |J_e qd - V_e|_W^2 / s + 1/2 |A qd - b|^2
                               s.t.  A qd = b,  G qd <= h,  lower <= qd <= upper
    stage 2 (posture):  qd   = qd_1 + N z,   N = null([A; W^1/2 J_e; E_1])
                        z    = argmin 1/2 |z - N^T (qd_posture - qd_1)|^2
                               s.t.  the other inequalities at qd_1 + N z

with ``E_1`` the inequality rows stage 1 holds with a non-zero multiplier.
``priorities="weighted"`` is the single weighted QP of section 10 instead.
"""

from __future__ import annotations

import functools
import math
from typing import Iterable, Literal, NamedTuple

import numpy as np
import pinocchio as pin
import qpsolvers
import scipy.sparse
from scipy.linalg import lapack

from constraints import Constraint
from constraints.validation import as_number, as_vector

from .base import (EQUALITY_TOLERANCE, Controller, Kinematics, SolverError, StepStatus,
                   as_twist_weight)
from .joint_limits import DEFAULT_LIMIT_GAIN
from .least_residual import HeldRows, held_rows, least_residual_problem
from .linalg import DampingPolicy, nullspace
from .qp_budget import (DAQP_OUT_OF_BUDGET, ITERATION_CAPS, BudgetExceeded, StepBudget,
                        TimeBudget)
from .task_damping import task_damping

Priorities = Literal["lexicographic", "weighted"]

#: Backends that take sparse matrices (given dense ones, qpsolvers converts and warns).
SPARSE_SOLVERS = frozenset({"osqp", "scs", "clarabel", "highs", "piqp", "qpalm"})

#: Tolerances per backend. The objectives are divided by the task's scale ``s``
#: (``QPController`` docstring), so their Hessians are of order one on every robot; the
#: primal residuals are in m/s (the constraint rows) and rad/s (the box). proxqp's
#: ``eps_abs`` and daqp's ``eta_prox`` are tightened per step to the curvature (see
#: :data:`TASK_ACCURACY`). OSQP (first order, ADMM) is asked for 1e-7 and polished; 20
#: refinement steps of its polishing (default 3) make the polished answer exact to about
#: 1e-11 rad/s on the generated chains, where 3 left up to 1e-4; its iteration cap is
#: 10^5 (2*10^4 stopped 3 of 20 semidefinite task stages on the 32-DoF chain with 8 holes
#: and binding limits; :data:`controllers.qp_budget.ITERATION_CAPS`). ``raise_error=False``
#: keeps OSQP's failures a "not found" status (as mink's settings do). Residuals are
#: reported, not hidden. Iteration caps and the time limit are the step budget's
#: (:mod:`controllers.qp_budget`).
SOLVER_SETTINGS: dict[str, dict] = {
    "proxqp": {"eps_abs": 1e-10, "eps_rel": 0.0},
    "daqp": {"primal_tol": 1e-10},
    "osqp": {"eps_abs": 1e-7, "eps_rel": 0.0, "polishing": True, "polish_refine_iter": 20,
             "raise_error": False},
}

#: Accuracy (rad/s) asked of the task stage along its weakest direction. A stationarity
#: residual ``r`` leaves ``qd`` off by ``r / lambda`` along a direction of curvature
#: ``lambda``, so proxqp gets ``eps_abs = TASK_ACCURACY * lambda_min`` and daqp's
#: proximal iterations ``eta_prox = TASK_ACCURACY * lambda_min`` (a step ``dx`` of
#: them leaves about ``dx / lambda_min``), each clipped to :data:`TOLERANCE_RANGE`.
#: ``lambda_min`` is the smallest non-zero eigenvalue of the normalised task Hessian:
#: about 1e-2 on the built-in robots, down to 3e-6 on the 64-DoF chain.
TASK_ACCURACY = 1e-8

#: Tightest and loosest tolerance the curvature may set. The tightest is what double
#: precision still resolves: proxqp's dual residual stalled at 3e-13 on a 64-DoF chain
#: with binding limits (then ``qd`` is within ``1e-12 / lambda_min``, 4e-7 rad/s there).
#: The loosest holds each constraint row to 1e-11 m/s under proxqp, whose ``eps_abs``
#: bounds the primal residual too: at 1e-10 a hole's two rows let the link cross its
#: axis at 1.2e-10 m/s.
TOLERANCE_RANGE = (1e-12, 1e-11)

#: proxqp's proximal parameter ``rho`` relative to ``lambda_min`` (at most proxqp's
#: default, 1e-6). Its default against a curvature of 1e-6 made the augmented Lagrangian
#: crawl: up to 65908 iterations on the generated chains with binding limits, 3 of 150
#: problems at the iteration cap; ``1e-4 lambda_min`` solved them all in at most 2563
#: (median 2).
PROXQP_RHO = 1e-4

#: daqp settings for a semidefinite task stage (a redundant robot: the task leaves
#: ``null([A; J_e])`` flat). daqp needs a positive definite Hessian, so it solves such a
#: problem by proximal-point iterations, ``min f(x) + eps_prox/2 |x - x_k|^2`` until
#: ``|x_(k+1) - x_k| <= eta_prox``: exact at the fixed point, so the task is not biased.
#: ``eps_prox`` is small against the normalised task curvatures, which then converge in
#: few iterations: over 720 task stages on the generated chains (8-64 DoF, 1-8 holes,
#: limits binding or not) a median of 6 outer iterations, at most 162.
DAQP_PROXIMAL_WEIGHT = 1e-8

#: The tightest ``eta_prox`` the curvature may set for daqp. Measured on the 64-DoF
#: chain: 1e-12 (proxqp's floor) left ``qd`` 2.5e-7 rad/s from the CJM's (at most 59
#: outer iterations), 1e-13 3e-8 (162), 1e-14 3e-9 but up to 3577 iterations.
DAQP_PROXIMAL_FLOOR = 1e-13

#: Weight of the posture term in the weighted QP, relative to the task's scale ``s``
#: (docs/design.md section 10 measures what it costs the task).
DEFAULT_POSTURE_WEIGHT = 1e-6

#: Singular values of ``[A; W^1/2 J_e / sqrt(s)]`` below this (relative to the largest,
#: at least 1) count as zero: the directions the posture stage may use. As the CJM's.
NULL_SPACE_RANK_TOLERANCE = 1e-10

#: The Cholesky shortcut of :func:`task_geometry` decides only where ``1 / |H^-1|_F``
#: exceeds this times the largest eigenvalue of ``H = M^T M``: forming ``M^T M`` rounds
#: away what lies below ``sqrt(eps)`` relative in ``M`` (a rank-deficient ``M``, as the
#: Panda's with a hole on its last link, factorised with a pivot of 1e-16), so anything
#: nearer singular goes to the SVD of ``M`` itself.
GRAM_CERTIFICATE = 1e-12

#: An inequality whose stage-1 multiplier exceeds this (normalised units), or the
#: backend's ``eps_abs`` if larger (OSQP's multipliers are only that accurate), is held
#: as an equality in stage 2: every task-optimal ``qd`` has it active (complementary
#: slackness), and left as an inequality it would make the posture QP degenerate (an
#: implicit equality: unbounded multipliers, on which proxqp stopped at a wrong point).
ACTIVE_MULTIPLIER = 1e-9

#: What stands for an infinite bound in the backends' constraints.
INFINITE_BOUND = 1e20

#: proxqp's threshold for certifying primal infeasibility (its ``eps_primal_inf``, a
#: field of the persistent objects' settings, which ``proxqp.dense.solve`` through
#: qpsolvers does not take). With the small ``rho`` of a redundant robot
#: (:data:`PROXQP_RHO`) its default 1e-4 certified infeasible, after 5 iterations, a task
#: stage it then solved in 110 (64-DoF chain, 8 holes); conflicting constraints are
#: still certified at 1e-8.
PROXQP_PRIMAL_INFEASIBILITY = 1e-8

#: proxqp settings that are arguments of ``init`` rather than fields of ``settings``.
_PROXQP_INIT_ARGUMENTS = frozenset({"rho", "mu_eq", "mu_in", "compute_preconditioner",
                                    "manual_minimal_H_eigenvalue"})


def held_note(residual: float) -> str:
    return (f"constraint rows conflict with the joint limits or barriers: held at their "
            f"least residual, {residual:.2e} m/s")


class QuadraticProgram(NamedTuple):
    """``min 1/2 x'Hx + g'x  s.t.  A x = b,  l <= C x <= u,  lower <= x <= upper``.

    Absent parts are None; an infinite bound is given as ``+-INFINITE_BOUND``.
    ``curvature`` is the smallest non-zero eigenvalue of ``H`` on the directions the
    objective sees (it sets the tolerances, :data:`TASK_ACCURACY`); ``semidefinite``
    says that ``H`` is singular on the feasible set, so that a backend needing a
    positive definite Hessian must regularise it without bias (daqp:
    :data:`DAQP_PROXIMAL_WEIGHT`).
    """

    hessian: np.ndarray
    gradient: np.ndarray
    equality_matrix: np.ndarray | None = None
    equality_rhs: np.ndarray | None = None
    rows: np.ndarray | None = None
    rows_lower: np.ndarray | None = None
    rows_upper: np.ndarray | None = None
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    curvature: float = 1.0
    semidefinite: bool = False

    @property
    def shape(self) -> tuple[int, int, int, bool]:
        """``(variables, equalities, rows, boxed)``: what a persistent solver is built for."""
        return (self.gradient.size,
                0 if self.equality_matrix is None else self.equality_matrix.shape[0],
                0 if self.rows is None else self.rows.shape[0],
                self.lower is not None)

    def tolerance(self) -> float:
        """``TASK_ACCURACY * curvature``, clipped to :data:`TOLERANCE_RANGE`."""
        return min(max(TASK_ACCURACY * self.curvature, TOLERANCE_RANGE[0]), TOLERANCE_RANGE[1])


class QPSolution(NamedTuple):
    """A backend's answer: ``x`` and the multipliers of the box and of the rows ``C``
    (positive at an upper bound, negative at a lower one; None where absent)."""

    x: np.ndarray
    box_multipliers: np.ndarray | None
    row_multipliers: np.ndarray | None


class TaskGeometry(NamedTuple):
    """``null(M)``, ``M = [A; W^1/2 J_e / sqrt(s)]``, and a curvature of the task Hessian
    ``M^T M``: its smallest non-zero eigenvalue, or a lower bound on it."""

    null_basis: np.ndarray
    curvature: float


def task_geometry(stacked_rows: np.ndarray, hessian: np.ndarray) -> TaskGeometry:
    """``null(M)`` and the curvature of ``hessian = M^T M`` (``M = stacked_rows``).

    Where ``M`` has at least as many rows as columns (no spare DoF on the built-in robots)
    a Cholesky factorisation usually settles it: ``1 / |H^-1|_F``, a lower bound on the
    smallest eigenvalue, above :data:`GRAM_CERTIFICATE` times the largest proves
    ``null(M)`` empty (the counterpart of the CJM's certified LU bound, docs/design.md
    section 4.3; about 10 us less than the SVD here). Otherwise one SVD of ``M`` gives
    both; singular values below ``NULL_SPACE_RANK_TOLERANCE`` (relative to the largest,
    at least 1) count as zero.
    """
    rows, columns = stacked_rows.shape
    if rows >= columns:
        factor, info = lapack.dpotrf(hessian, lower=1, clean=1)
        if info == 0:
            inverse, info = lapack.dpotrs(factor, _identity(columns), lower=1)
            bound = 1.0 / math.sqrt(float(np.vdot(inverse, inverse))) if info == 0 else 0.0
            largest = max(1.0, float(np.trace(hessian)))  # >= the largest eigenvalue
            if bound > GRAM_CERTIFICATE * largest:
                return TaskGeometry(np.zeros((columns, 0)), bound)
    _, singular_values, right_vectors, info = lapack.dgesdd(stacked_rows, full_matrices=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"SVD did not converge (LAPACK dgesdd info {info})")
    values = singular_values.tolist()
    tolerance = NULL_SPACE_RANK_TOLERANCE * max(1.0, values[0]) if values else 0.0
    rank = sum(1 for value in values if value > tolerance)
    curvature = values[rank - 1] ** 2 if rank else 1.0
    return TaskGeometry(right_vectors[rank:].T.copy(), curvature)


@functools.lru_cache(maxsize=8)
def _identity(size: int) -> np.ndarray:
    """A read-only ``size x size`` identity (the right-hand side of the inverse bound)."""
    identity = np.eye(size)
    identity.setflags(write=False)
    return identity


def _daqp_accepts(settings: dict) -> bool:
    """Whether every key is a daqp setting ``daqp.solve`` takes (else: qpsolvers)."""
    import daqp  # noqa: PLC0415 - only when daqp is the backend

    return all(k in daqp.Model().settings for k in settings)


class ProxQPSolver:
    """Persistent ``proxsuite.proxqp.dense.QP`` objects: ``init`` once per problem shape,
    ``update`` + ``solve`` after.

    The task stage and the posture stage have different shapes, so each gets its own
    object (keyed by :attr:`QuadraticProgram.shape`). The joint bounds go in proxsuite's
    box constraints, the other inequality rows in ``C``. All objects are dropped after a
    failed solve, so that a bad state never carries over. ``update`` keeps the
    preconditioner of ``init``: recomputing it every step cost more than it saved, and
    the stopping test is on the unscaled residuals, so the tolerances hold either way.
    It restarts the penalty parameters ``mu_eq``, ``mu_in`` from their initial values,
    as ``init`` does: carried over from the previous step, they made proxqp stop at a
    wrong point reported as solved (the task missed by 2e-4 m/s), at a spurious
    infeasibility or at the iteration cap on the generated chains with binding limits.
    proxqp takes a semidefinite Hessian as it is: its proximal term acts only while it
    iterates, and directions the objective does not see feel no force.

    ``initial_guess`` (a ``proxsuite.proxqp.InitialGuess`` name, in ``solver_settings``)
    defaults to ``EQUALITY_CONSTRAINED_INITIAL_GUESS``, which is what a fresh proxqp
    solve uses: measured on the built-in robots it needs no more iterations than
    ``WARM_START_WITH_PREVIOUS_RESULT`` (2 per step on a smooth closed loop, for both),
    and warm starting from the previous result now and then stopped at a spurious
    ``PROXQP_PRIMAL_INFEASIBLE`` on independent configurations. With a warm start
    chosen, a step that does not reach ``PROXQP_SOLVED`` is solved again from the
    equality-constrained guess before it is reported as a failure.
    """

    def __init__(self, settings: dict, tuned: frozenset[str]) -> None:
        import proxsuite  # noqa: PLC0415 - only when proxqp is the backend

        self._proxqp = proxsuite.proxqp
        self.init_arguments = {k: v for k, v in settings.items() if k in _PROXQP_INIT_ARGUMENTS}
        self.settings = {"eps_primal_inf": PROXQP_PRIMAL_INFEASIBILITY,
                         **{k: v for k, v in settings.items() if k not in _PROXQP_INIT_ARGUMENTS}}
        guess = self.settings.pop("initial_guess", "EQUALITY_CONSTRAINED_INITIAL_GUESS")
        if isinstance(guess, str):
            if guess not in proxsuite.proxqp.InitialGuess.__members__:
                raise ValueError(f"unknown proxqp initial_guess {guess!r}; one of "
                                 f"{list(proxsuite.proxqp.InitialGuess.__members__)}")
            guess = proxsuite.proxqp.InitialGuess.__members__[guess]
        self.initial_guess = guess
        self.fallback_guess = proxsuite.proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
        self.solved = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
        self.tuned = tuned  # of "eps_abs", "rho": set from the curvature, per solve
        self.solvers: dict[tuple[int, int, int, bool], object] = {}

    @staticmethod
    def accepts(settings: dict) -> bool:
        """Whether every key is a proxqp setting this class can apply (else: qpsolvers)."""
        import proxsuite  # noqa: PLC0415

        fields = set(dir(proxsuite.proxqp.dense.QP(1, 0, 0).settings))
        return all(k in fields or k in _PROXQP_INIT_ARGUMENTS for k in settings)

    def reset(self) -> None:
        self.solvers.clear()

    def solve(self, problem: QuadraticProgram, budget: StepBudget) -> QPSolution:
        budget.remaining("proxqp")
        shape = problem.shape
        _, _, n_rows, boxed = shape
        arguments = (problem.hessian, problem.gradient, problem.equality_matrix,
                     problem.equality_rhs, problem.rows, problem.rows_lower, problem.rows_upper,
                     *((problem.lower, problem.upper) if boxed else ()))
        proximal = ({"rho": min(1e-6, PROXQP_RHO * problem.curvature)}
                    if "rho" in self.tuned else {})
        qp = self.solvers.get(shape)
        if qp is None:
            qp = self._proxqp.dense.QP(*shape[:3], box_constraints=boxed)
            for key, value in self.settings.items():
                setattr(qp.settings, key, value)
            qp.settings.initial_guess = self.initial_guess
            if "eps_abs" in self.tuned:
                qp.settings.eps_abs = problem.tolerance()
            qp.init(*arguments, **self.init_arguments, **proximal)
            self.solvers[shape] = qp
        else:
            if "eps_abs" in self.tuned:
                qp.settings.eps_abs = problem.tolerance()
            penalties = {"mu_eq": self.init_arguments.get("mu_eq", qp.settings.default_mu_eq),
                         "mu_in": self.init_arguments.get("mu_in", qp.settings.default_mu_in)}
            qp.update(*arguments, **proximal, **penalties)
        qp.solve()
        status = qp.results.info.status
        if status != self.solved and self.initial_guess != self.fallback_guess:
            qp.settings.initial_guess = self.fallback_guess
            qp.solve()
            qp.settings.initial_guess = self.initial_guess
            status = qp.results.info.status
        if status != self.solved:
            self.reset()
            if status == self._proxqp.QPSolverOutput.PROXQP_MAX_ITER_REACHED:
                raise budget.exceeded("proxqp", f"iteration limit ({qp.settings.max_iter} "
                                      f"x {qp.settings.max_iter_in} iterations)")
            raise SolverError(f"proxqp found no solution ({status.name})")
        multipliers = qp.results.z  # the rows C, then the box
        return QPSolution(qp.results.x.copy(), multipliers[n_rows:].copy() if boxed else None,
                          multipliers[:n_rows].copy() if n_rows else None)


class QPController(Controller):
    """Joint velocities from a QP with the CJM's priorities: rows, then twist, then posture.

    ::

        rows (hard)       A qd = b                         equality rows, same drift as the CJM
                          G qd <= h                        barrier rows: -n.v_c <= K d - n.v_plane
                          max(-qd_max, g (q_min - q)/dt) <= qd <= min(qd_max, g (q_max - q)/dt)
        task              min |J_e qd - V_e|_W^2            (least squares)
        posture           min |qd - qd_posture|^2,   qd_posture = posture_gain * (posture (-) q)

    **Lexicographic** (default, docs/design.md section 10): the task QP (stage 1), then
    the posture QP over the task's optimal set (stage 2), written in
    ``N = null([A; W^1/2 J_e; E_1])`` so that the rows, the achieved twist
    ``J_e qd = J_e qd_1`` and the inequalities stage 1 holds with a non-zero multiplier
    (``E_1``) hold by construction: no rank-deficient or implicit equality reaches a
    backend, and the posture QP has the identity as Hessian. When
    ``qd_1 + N N^T (qd_posture - qd_1)`` satisfies the other inequalities it is the
    answer, without a second solve. With no inequality binding that is the CJM's command
    (general form, docs/design.md section 4.5) wherever the CJM does not damp. A robot
    with no spare DoF (``N`` empty) solves stage 1 only.

    **Weighted** (``priorities="weighted"``): one QP,
    ``min 1/2 |J_e qd - V_e|_W^2 / s + 1/2 mu |qd - qd_posture|^2`` under the same rows.
    The posture then bends the task by about ``mu / lambda`` along a task direction of
    normalised curvature ``lambda``; section 10 gives the measured deviation.

    **Scale.** Both objectives are divided by ``s = |W^1/2 J_e|_F^2 / m`` (``m`` rows: 6
    per end effector), the mean
    squared singular value of the weighted task Jacobian, and carry ``1/2 |A qd - b|^2``,
    which is zero on the feasible set: the task Hessian is then
    ``M^T M``, ``M = [A; W^1/2 J_e / sqrt(s)]``, of order one whatever the robot's size
    and definite wherever the rows or the task see a direction. One SVD of ``M`` (or,
    with no spare DoF, a Cholesky factorisation of ``M^T M``: :func:`task_geometry`)
    gives the null space of stage 2 and the smallest curvature ``lambda_min``, from
    which proxqp's and daqp's tolerances are set (:data:`TASK_ACCURACY`).

    Parameters
    ----------
    robot, constraints, dt, limit_gain, position_limits, velocity_limits, strict : see
        :class:`controllers.base.Controller`.
    solver : a ``qpsolvers`` backend: ``"proxqp"`` (default), ``"daqp"``, ``"osqp"``, ...
        proxqp runs as persistent ``proxsuite`` dense QPs (``init`` once per stage, then
        ``update`` + ``solve``; see :class:`ProxQPSolver`), daqp through ``daqp.solve``
        directly, the others through ``qpsolvers``. ``solver_settings`` the direct calls cannot apply
        (a key that is no proxqp/daqp setting) send proxqp/daqp through ``qpsolvers`` too.
    priorities : ``"lexicographic"`` (default) or ``"weighted"``.
    posture : configuration the redundancy is spent on (default ``robot.q_home``), as
        the CJM's.
    posture_gain : gain (1/s) of the posture velocity, as the CJM's; 0 gives the
        minimum-norm ``qd`` among those the rows and the task leave.
    mu : weight of the posture term in the weighted QP, relative to the task's scale
        ``s`` (the lexicographic solve has no such weight).
    twist_weight : (6,) diagonal weight ``W`` of each EE's twist error, or one weight per
        entry of the stacked twist (default identity).
    solver_settings : extra keyword arguments for the backend (override the defaults,
        the tolerances set from the curvature included, and the iteration caps).
    time_budget : the step's deadline in CPU seconds: ``"periods"`` (default, 10 control
        periods), a number, or None for the iteration caps alone (simulated time);
        docs/design.md section 10.6.
    damping, singular_threshold, max_damping : the CJM's damping policy (paper eq 35),
        applied to the task stage as rows (docs/design.md section 10.7).
    """

    def __init__(
        self,
        robot,
        constraints: Iterable[Constraint] = (),
        solver: str = "proxqp",
        dt: float = 1e-3,
        priorities: Priorities = "lexicographic",
        posture: np.ndarray | None = None,
        posture_gain: float = 1.0,
        mu: float = DEFAULT_POSTURE_WEIGHT,
        twist_weight=None,
        limit_gain: float = DEFAULT_LIMIT_GAIN,
        position_limits: bool = True,
        velocity_limits: bool = True,
        solver_settings: dict | None = None,
        time_budget: TimeBudget = "periods",
        damping: float = 0.0,
        singular_threshold: float = 0.01,
        max_damping: float = 0.05,
        strict: bool = False,
    ) -> None:
        super().__init__(robot, dt=dt, limit_gain=limit_gain, position_limits=position_limits,
                         velocity_limits=velocity_limits, strict=strict)
        self.budget = StepBudget(time_budget, self.dt)
        self.policy = DampingPolicy(as_number(damping, "damping", 0.0),
                                    as_number(singular_threshold, "singular_threshold", 0.0),
                                    as_number(max_damping, "max_damping", 0.0))
        if solver not in qpsolvers.available_solvers:
            raise ValueError(
                f"QP solver {solver!r} is not available; installed: {qpsolvers.available_solvers}"
            )
        if priorities not in ("lexicographic", "weighted"):
            raise ValueError(f"unknown priorities {priorities!r}: 'lexicographic' or 'weighted'")
        self.solver = solver
        self.priorities: Priorities = priorities
        self.mu = as_number(mu, "mu", positive=True)
        self.posture_gain = as_number(posture_gain, "posture_gain", 0.0)
        if posture is None:
            posture = getattr(robot, "q_home", None)
        self.posture = (pin.neutral(self.model) if posture is None
                        else as_vector(posture, self.model.nq, "posture"))
        user_settings = dict(solver_settings or {})
        self.settings = {**SOLVER_SETTINGS.get(solver, {}), **ITERATION_CAPS.get(solver, {}),
                         **user_settings}
        weight = as_twist_weight(twist_weight, self.task_size)
        self.twist_weight = weight
        self._twist_scale = np.sqrt(weight)
        self._twist_rows = self._twist_scale[:, None]  # W^1/2, to scale the rows of J_e
        self._unit_weight = bool(np.all(weight == 1.0))
        #: the task rows the damping sees: those of non-zero weight, as the CJM's
        self._weighted_rows = np.flatnonzero(weight > 0.0)
        self._stacked, self._stacked_target = np.empty((0, self.model.nv)), np.empty(0)
        self._daqp_buffers: dict[tuple[int, int, int], tuple[np.ndarray, ...]] = {}
        # proxqp and daqp are called directly (persistent proxqp objects; daqp.solve),
        # the other backends through qpsolvers. Settings a direct call cannot apply
        # send proxqp and daqp back through qpsolvers as well.
        self._proxqp = (ProxQPSolver(self.settings,
                                     frozenset({"eps_abs", "rho"} - set(user_settings)))
                        if solver == "proxqp" and ProxQPSolver.accepts(self.settings) else None)
        self._direct_daqp = solver == "daqp" and _daqp_accepts(self.settings)
        #: what goes through qpsolvers: its proxqp path takes no inner cap (``max_iter_in``)
        self._qpsolvers_settings = {k: v for k, v in self.settings.items()
                                    if not (solver == "proxqp" and k == "max_iter_in")}
        if self._direct_daqp:
            import daqp  # noqa: PLC0415 - only when daqp is the backend

            self._daqp = daqp
            #: the proximal settings of a semidefinite stage the user did not set
            self._daqp_proximal_keys = {"eps_prox", "eta_prox"} - set(user_settings)
        self.set_constraints(constraints)

    def _prepare(self) -> None:
        self._equalities = [i for i, k in enumerate(self.constraints) if k.is_equality]
        self._barriers = [i for i, k in enumerate(self.constraints) if not k.is_equality]
        if self._proxqp is not None:
            self._proxqp.reset()

    # -- the step ----------------------------------------------------------------------

    def posture_velocity(self, q: np.ndarray) -> np.ndarray:
        """``posture_gain * (posture (-) q)`` (nv,): the CJM's posture velocity."""
        if self.posture_gain == 0.0:
            return np.zeros(self.model.nv)
        return self.posture_gain * self.posture_difference(q, self.posture)

    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        self.budget.start()
        self.info.method = f"qp:{self.solver}"
        jacobian = kinematics.ee_jacobian
        A, b = self.constraint_rows(self._equalities) if self._equalities else (None, None)
        barrier_rows = barrier_bound = None
        if self._barriers:
            rows, rhs = self.constraint_rows(self._barriers)
            barrier_rows, barrier_bound = -rows, -rhs  # A qd >= b as -A qd <= -b
        lower, upper = self._box(kinematics.q)
        weighted_jacobian = jacobian if self._unit_weight else self._twist_rows * jacobian
        damping = task_damping(A, weighted_jacobian[self._weighted_rows], self.policy)
        self.info.sigma_min, self.info.damping = damping.sigma_min, damping.damping
        try:
            qd = self._prioritised(kinematics.q, weighted_jacobian, twist, damping.rows,
                                   A, b, barrier_rows, barrier_bound, lower, upper)
        except SolverError as error:  # infeasible, or out of iterations (proxqp's sign of it)
            if A is None and barrier_rows is None:
                raise
            try:
                held = self._least_residual(A, b, barrier_rows, barrier_bound, lower, upper)
            except SolverError as second:
                raise error from second
            if held.residual <= EQUALITY_TOLERANCE:
                raise  # the rows fit the limits: the failure was something else
            self.info.report(StepStatus.CONSTRAINT_DEGRADED, held_note(held.residual))
            try:
                qd = self._prioritised(kinematics.q, weighted_jacobian, twist, damping.rows,
                                       held.rows, held.rhs, barrier_rows, held.barrier_bound,
                                       lower, upper)
            except BudgetExceeded:
                raise
            except SolverError as task_error:
                qd = held.qd
                self.info.report(StepStatus.LEAST_SQUARES, f"task stage under the held rows "
                                 f"failed ({task_error}): the least-residual command")
            barrier_bound = held.barrier_bound
        if A is not None:
            self.info.equality_residual = max(map(abs, (np.dot(A, qd) - b).tolist()))
        if barrier_rows is not None:
            held_barriers = np.flatnonzero(barrier_rows @ qd - barrier_bound > -1e-9)
            self.info.active_barriers = tuple(self._barriers[i] for i in held_barriers)
        self._report_twist_error(jacobian, qd, twist,
                                 None if self._unit_weight else self._twist_scale)
        return qd

    def _prioritised(self, q: np.ndarray, weighted_jacobian: np.ndarray, twist: np.ndarray,
                     damping_rows: np.ndarray, A: np.ndarray | None, b: np.ndarray | None,
                     barrier_rows: np.ndarray | None, barrier_bound: np.ndarray | None,
                     lower: np.ndarray | None, upper: np.ndarray | None) -> np.ndarray:
        """The lexicographic (or weighted) solve under the rows ``A qd = b``, the barriers
        ``barrier_rows qd <= barrier_bound`` and the box (docs/design.md section 10)."""
        nv = self.model.nv
        k = 0 if A is None else A.shape[0]
        d = damping_rows.shape[0]
        # M = [A; W^1/2 J / sqrt(s); D / sqrt(s)]: the task Hessian is M^T M, and the
        # objective 1/2 (|J qd - V|_W^2 + |D qd|^2) / s + 1/2 |A qd - b|^2 has gradient
        # -M^T [b; W^1/2 V / sqrt(s); 0]
        m = self.task_size
        if self._stacked.shape[0] != k + m + d:
            self._stacked, self._stacked_target = np.empty((k + m + d, nv)), np.empty(k + m + d)
        stacked, stacked_target = self._stacked, self._stacked_target
        square_sum = float(np.vdot(weighted_jacobian, weighted_jacobian))
        inverse_root_scale = math.sqrt(m / square_sum) if square_sum > 0.0 else 1.0
        np.multiply(weighted_jacobian, inverse_root_scale, out=stacked[k:k + m])
        np.multiply(twist if self._unit_weight else self._twist_scale * twist,
                    inverse_root_scale, out=stacked_target[k:k + m])
        if k:
            stacked[:k] = A
            stacked_target[:k] = b
        if d:
            np.multiply(damping_rows, inverse_root_scale, out=stacked[k + m:])
            stacked_target[k + m:] = 0.0
        hessian = np.dot(stacked.T, stacked)
        gradient = np.dot(stacked_target, stacked)
        np.negative(gradient, out=gradient)
        barrier_lower = None if barrier_rows is None else np.full(barrier_rows.shape[0],
                                                                   -INFINITE_BOUND)
        if self.priorities == "weighted":
            hessian.flat[::nv + 1] += self.mu  # + mu I
            gradient -= self.mu * self.posture_velocity(q)
            return self._solve_qp(QuadraticProgram(
                hessian, gradient, A, b, barrier_rows, barrier_lower, barrier_bound,
                lower, upper, curvature=self.mu)).x
        geometry = task_geometry(stacked, hessian)
        spare = geometry.null_basis.shape[1] > 0
        task = QuadraticProgram(hessian, gradient, A, b, barrier_rows, barrier_lower,
                                barrier_bound, lower, upper, geometry.curvature, spare)
        stage_1 = self._solve_qp(task)
        if not spare:
            return stage_1.x
        return self._posture_stage(stage_1, geometry.null_basis, self.posture_velocity(q),
                                   task, stacked, stacked_target)

    def _least_residual(self, A: np.ndarray | None, b: np.ndarray | None,
                        barrier_rows: np.ndarray | None, barrier_bound: np.ndarray | None,
                        lower: np.ndarray | None, upper: np.ndarray | None) -> HeldRows:
        """The rows as close to ``b`` as the box and the barriers allow
        (:mod:`controllers.least_residual`)."""
        nv = self.model.nv
        if lower is None:
            lower, upper = np.full(nv, -INFINITE_BOUND), np.full(nv, INFINITE_BOUND)
        problem = least_residual_problem(A, b, barrier_rows, barrier_bound, lower, upper,
                                         INFINITE_BOUND)
        solution = self._solve_qp(QuadraticProgram(
            problem.hessian, problem.gradient, rows=problem.rows,
            rows_lower=problem.rows_lower, rows_upper=problem.rows_upper,
            lower=problem.lower, upper=problem.upper, curvature=problem.curvature,
            semidefinite=problem.semidefinite))
        return held_rows(solution.x, A, b, barrier_rows, barrier_bound, lower, upper)

    def _box(self, q: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The joint box at ``q`` with ``+-INFINITE_BOUND`` for no bound; None if none."""
        lower, upper = self.joint_bounds.box(q)
        if not math.isfinite(sum(lower.tolist()) + sum(upper.tolist())):
            if not (np.isfinite(lower).any() or np.isfinite(upper).any()):
                return None, None  # nothing bounded
            lower = np.where(np.isfinite(lower), lower, -INFINITE_BOUND)
            upper = np.where(np.isfinite(upper), upper, INFINITE_BOUND)
        return lower, upper

    def _posture_stage(self, stage_1: QPSolution, null_basis: np.ndarray,
                       posture_velocity: np.ndarray, task: QuadraticProgram,
                       stacked: np.ndarray, stacked_target: np.ndarray) -> np.ndarray:
        """Stage 2 of the lexicographic solve (docs/design.md section 10).

        Every ``qd_1 + N z`` holds the rows and the achieved twist as ``qd_1`` does
        (``A N = 0``, ``J_e N = 0``). The inequalities stage 1 holds with a multiplier
        above :data:`ACTIVE_MULTIPLIER` (or the backend's ``eps_abs``) are active at
        every task-optimal ``qd``, so they join ``N``'s equalities
        (:meth:`_polish_on_face`, which also removes the task stage's tolerance from
        ``qd_1``). The posture QP is then over ``z`` alone, with
        the identity as Hessian: ``min 1/2 |z - N^T (qd_posture - qd_1)|^2`` under the
        other inequalities, whose bounds are widened to hold ``z = 0`` (``qd_1`` may sit
        outside by the task solve's tolerance; the base class clips that back). Where the
        unconstrained minimiser already fits, it is the answer without a solve.
        """
        qd_1 = stage_1.x
        active = max(ACTIVE_MULTIPLIER, self.settings.get("eps_abs", 0.0))
        held_joints = (np.zeros(qd_1.size, dtype=bool) if stage_1.box_multipliers is None
                       else np.abs(stage_1.box_multipliers) > active)
        held_rows = (np.zeros(0 if task.rows is None else task.rows.shape[0], dtype=bool)
                     if stage_1.row_multipliers is None
                     else np.abs(stage_1.row_multipliers) > active)
        if held_joints.any() or held_rows.any():
            qd_1, null_basis = self._polish_on_face(stage_1, held_joints, held_rows, null_basis,
                                                    task, stacked, stacked_target)
            if not null_basis.shape[1]:
                return qd_1
        target = np.dot(posture_velocity - qd_1, null_basis)
        move = np.dot(null_basis, target)
        blocks, lows, highs = [], [], []
        if task.lower is not None:
            free = np.flatnonzero(~held_joints & ((task.lower > -INFINITE_BOUND)
                                                  | (task.upper < INFINITE_BOUND)))
            blocks.append(null_basis[free])
            lows.append(np.minimum(task.lower[free] - qd_1[free], 0.0))
            highs.append(np.maximum(task.upper[free] - qd_1[free], 0.0))
        if task.rows is not None:
            free = np.flatnonzero(~held_rows)
            blocks.append(task.rows[free] @ null_basis)
            lows.append(np.full(free.size, -INFINITE_BOUND))
            highs.append(np.maximum(task.rows_upper[free] - task.rows[free] @ qd_1, 0.0))
        rows = np.vstack(blocks) if blocks else np.zeros((0, target.size))
        rows_lower = np.concatenate(lows) if lows else np.zeros(0)
        rows_upper = np.concatenate(highs) if highs else np.zeros(0)
        reached = rows @ target
        if np.all(reached >= rows_lower) and np.all(reached <= rows_upper):
            return qd_1 + move
        posture = QuadraticProgram(np.eye(target.size), -target, rows=rows,
                                   rows_lower=rows_lower, rows_upper=rows_upper)
        return qd_1 + null_basis @ self._solve_qp(posture).x

    def _polish_on_face(self, stage_1: QPSolution, held_joints: np.ndarray,
                        held_rows: np.ndarray, null_basis: np.ndarray, task: QuadraticProgram,
                        stacked: np.ndarray, stacked_target: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
        """``(qd_1, N)`` on the face of the inequalities stage 1 holds (docs/design.md 10.1).

        ``N`` is narrowed to ``null(E)``, ``E`` the held rows (a joint at its bound, a
        barrier). ``qd_1`` is polished (OSQP's polish, for every backend): on the face ``F``
        of the rows, the held rows and any other inequality ``qd_1`` sits on (to
        :data:`EQUALITY_TOLERANCE`), the task stage is a least-squares problem, solved
        here exactly from ``qd_1``: ``qd_F = qd_f + Z (M Z)^+ (m - M qd_f)``, ``qd_f`` the
        nearest point of ``F`` to ``qd_1``, ``Z = null(F)``, ``m`` the stacked target.
        That removes the task solve's tolerance, which a nearly degenerate posture
        polytope amplified: proxqp's 2e-8 m/s became 1.3e-5 rad/s on a 32-DoF chain
        with 8 holes. ``qd_F`` moves ``qd_1`` only across ``N``, and is kept when it
        meets the other inequalities to ``EQUALITY_TOLERANCE`` and misses the task by no
        more than ``qd_1`` (+1e-12); else ``qd_1`` stays.
        """
        qd_1 = stage_1.x
        held = ([np.eye(qd_1.size)[held_joints]] if held_joints.any() else []) + (
            [task.rows[held_rows]] if held_rows.any() else [])
        narrowed = null_basis @ nullspace(np.vstack(held) @ null_basis,
                                          NULL_SPACE_RANK_TOLERANCE)[0]
        on_joints, on_rows = held_joints.copy(), held_rows.copy()
        face, face_target = [], []
        if task.equality_matrix is not None:
            face.append(task.equality_matrix)
            face_target.append(task.equality_rhs)
        if task.lower is not None:
            at_upper = qd_1 >= task.upper - EQUALITY_TOLERANCE
            if held_joints.any():  # a held joint's side is its multiplier's
                at_upper[held_joints] = stage_1.box_multipliers[held_joints] > 0.0
            on_joints |= at_upper | (qd_1 <= task.lower + EQUALITY_TOLERANCE)
            face.append(np.eye(qd_1.size)[on_joints])
            face_target.append(np.where(at_upper, task.upper, task.lower)[on_joints])
        if task.rows is not None:
            on_rows |= task.rows @ qd_1 >= task.rows_upper - EQUALITY_TOLERANCE
            face.append(task.rows[on_rows])
            face_target.append(task.rows_upper[on_rows])
        face, face_target = np.vstack(face), np.concatenate(face_target)
        face_basis, face_pinv, _ = nullspace(face, NULL_SPACE_RANK_TOLERANCE)
        on_face = qd_1 + face_pinv @ (face_target - face @ qd_1)
        task_on_face = stacked @ face_basis
        step = np.linalg.lstsq(task_on_face, stacked_target - stacked @ on_face,
                               rcond=NULL_SPACE_RANK_TOLERANCE)[0]
        polished = on_face + face_basis @ step
        if self._polish_holds(polished, qd_1, ~on_joints, ~on_rows, face, face_target, task,
                              stacked, stacked_target):
            return polished, narrowed
        return qd_1, narrowed

    @staticmethod
    def _polish_holds(polished: np.ndarray, qd_1: np.ndarray, free_joints: np.ndarray,
                      free_rows: np.ndarray, face: np.ndarray, face_target: np.ndarray,
                      task: QuadraticProgram, stacked: np.ndarray, stacked_target: np.ndarray
                      ) -> bool:
        """Whether the polished ``qd`` holds its face and the other inequalities to
        ``EQUALITY_TOLERANCE`` and misses the task by no more than ``qd_1`` (+1e-12)."""
        if np.max(np.abs(face @ polished - face_target)) > EQUALITY_TOLERANCE:
            return False  # the face's rows are not consistent
        if task.lower is not None and not (
                np.all(polished[free_joints] >= task.lower[free_joints] - EQUALITY_TOLERANCE)
                and np.all(polished[free_joints] <= task.upper[free_joints] + EQUALITY_TOLERANCE)):
            return False
        if task.rows is not None and free_rows.any() and np.any(
                task.rows[free_rows] @ polished > task.rows_upper[free_rows] + EQUALITY_TOLERANCE):
            return False
        return bool(np.linalg.norm(stacked @ polished - stacked_target)
                    <= np.linalg.norm(stacked @ qd_1 - stacked_target) + 1e-12)

    # -- backends ----------------------------------------------------------------------

    def _solve_qp(self, problem: QuadraticProgram) -> QPSolution:
        if self._proxqp is not None:
            return self._proxqp.solve(problem, self.budget)
        if self._direct_daqp:
            return self._solve_daqp(problem)
        return self._solve_qpsolvers(problem)

    def _solve_daqp(self, problem: QuadraticProgram) -> QPSolution:
        """``daqp.solve`` directly (what qpsolvers does, without its ``Problem`` layer).

        Rows: the joint bounds first (daqp's simple bounds), then the inequality rows,
        then the equalities (``sense`` 5). A semidefinite problem is solved by daqp's
        proximal-point iterations (:data:`DAQP_PROXIMAL_WEIGHT`, ``eta_prox`` from the
        curvature). ``daqp.Model`` (a persistent workspace that keeps the active set) was
        measured too: about 1 us slower per step here, on independent and on smooth
        sequences alike.
        """
        variables, n_eq, n_rows, boxed = problem.shape
        n_box = variables if boxed else 0
        shape = (n_box, n_rows, n_eq)
        buffers = self._daqp_buffers.get(shape)
        if buffers is None:  # bound vectors and constraint types, per shape
            sense = np.zeros(n_box + n_rows + n_eq, dtype=np.intc)
            sense[n_box + n_rows:] = 5
            buffers = (np.empty(sense.size), np.empty(sense.size), sense)
            self._daqp_buffers[shape] = buffers
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
        self.budget.remaining("daqp")
        settings = self.settings
        if problem.semidefinite and self._daqp_proximal_keys:
            proximal = {"eps_prox": DAQP_PROXIMAL_WEIGHT,
                        "eta_prox": min(max(TASK_ACCURACY * problem.curvature, DAQP_PROXIMAL_FLOOR),
                                        TOLERANCE_RANGE[1])}
            settings = {**settings, **{k: proximal[k] for k in self._daqp_proximal_keys}}
        try:
            x, _, exitflag, info = self._daqp.solve(problem.hessian, problem.gradient, rows, upper,
                                                    lower, sense, **settings)
        except Exception as error:  # the backend raises its own types
            raise SolverError(f"daqp raised {type(error).__name__}: {error}") from error
        if exitflag in DAQP_OUT_OF_BUDGET:
            raise self.budget.exceeded("daqp", DAQP_OUT_OF_BUDGET[exitflag])
        if exitflag <= 0:
            raise SolverError(f"daqp found no solution (exit flag {exitflag})")
        multipliers = info["lam"]
        return QPSolution(x, multipliers[:n_box] if boxed else None,
                          multipliers[n_box:n_box + n_rows] if n_rows else None)

    def _solve_qpsolvers(self, problem: QuadraticProgram) -> QPSolution:
        """The problem through ``qpsolvers`` (two-sided rows as two one-sided blocks)."""
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
        if self.solver in SPARSE_SOLVERS:
            P = scipy.sparse.csc_matrix(P)
            A = None if A is None else scipy.sparse.csc_matrix(A)
            G = None if G is None else scipy.sparse.csc_matrix(G)
        qp = qpsolvers.Problem(P, problem.gradient, G, h, A, problem.equality_rhs,
                               lb=problem.lower, ub=problem.upper)
        left = self.budget.remaining(self.solver)
        settings = self._qpsolvers_settings
        if self.solver == "osqp" and math.isfinite(left):  # one solve bounded by what is left
            settings = {**settings, "time_limit": left}
        try:
            solution = qpsolvers.solve_problem(qp, solver=self.solver, **settings)
        except Exception as error:  # backends raise their own types
            raise SolverError(f"{self.solver} raised {type(error).__name__}: {error}") from error
        if not solution.found or solution.x is None:
            status = str(getattr(solution.extras.get("info"), "status", ""))
            if "time limit" in status or "maximum iterations" in status:
                raise self.budget.exceeded(self.solver, status)
            raise SolverError(f"{self.solver} found no solution "
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
