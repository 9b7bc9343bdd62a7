"""The QP controller: the CJM's priorities as quadratic programs (docs/design.md 4.7, 10).

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

from typing import Iterable, Literal

import numpy as np
import pinocchio as pin
import qpsolvers

from constraints import Constraint
from constraints.collision import CollisionAvoidance, CollisionRows
from constraints.validation import as_number, as_vector

from ..base import (EQUALITY_TOLERANCE, GuardedController, Kinematics, SolverError, StepStatus,
                    as_twist_weight, posture_difference, report_twist_error)
from ..joint_acceleration import braked_lower, braked_pairs
from ..joint_limits import DEFAULT_LIMIT_GAIN
from ..linalg import DampingPolicy
from ..numerics import INFINITE_BOUND, OSQP_CAPPED_SETTINGS, SOLVER_SETTINGS
from ..optimization.budget import ITERATION_CAPS, BudgetExceeded, StepBudget, TimeBudget
from ..optimization.collision_report import (AT_BOUND, pair_list, pair_names, record_distances,
                                             report_conflict, report_held_back, rows_at_bound)
from ..optimization.least_residual import HeldRows, held_note, held_rows, least_residual_problem
from ..optimization.problem import QPSolution, QuadraticProgram
from ..optimization.proxqp import ProxQPSolver
from ..optimization.task_damping import TaskDamping, task_damping
from .assembly import TaskAssembly, bounded_box
from .daqp_direct import DirectDAQP
from .geometry import task_geometry
from .posture_stage import posture_stage
from .reduced import eliminated, nearly_fixed, restored
from .qpsolvers_path import solve_with_qpsolvers

Priorities = Literal["lexicographic", "weighted"]

#: Weight of the posture term in the weighted QP, relative to the task's scale ``s``
#: (docs/design.md section 10 measures what it costs the task).
DEFAULT_POSTURE_WEIGHT = 1e-6


class QPController(GuardedController):
    """Joint velocities from a QP with the CJM's priorities: rows, then twist, then posture.

    ::

        rows (hard)       A qd = b                         equality rows, same drift as the CJM
                          G qd <= h                        barrier rows: -n.v_c <= K d - n.v_plane
                                                           collision rows: -d_dot <= k (d - d_s)
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
    which proxqp's and daqp's tolerances are set
    (:data:`controllers.numerics.TASK_ACCURACY`).

    Parameters
    ----------
    robot, constraints, dt, limit_gain, position_limits, velocity_limits, strict,
    acceleration_limit, collisions : see
        :class:`controllers.base.Controller`. The collision rows ``rows qd >= lower``
        join the barriers' rows as inequalities in every stage (docs/design.md 18.5).
    solver : a ``qpsolvers`` backend: ``"proxqp"`` (default), ``"daqp"``, ``"osqp"``, ...
        proxqp runs as persistent ``proxsuite`` dense QPs (``init`` once per stage, then
        ``update`` + ``solve``; see
        :class:`controllers.optimization.proxqp.ProxQPSolver`), daqp through ``daqp.solve``
        directly, the others through ``qpsolvers``. ``solver_settings`` the direct calls
        cannot apply (a key that is no proxqp/daqp setting) send proxqp/daqp through
        ``qpsolvers`` too.
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
        acceleration_limit=None,
        collisions: CollisionAvoidance | None = None,
        jerk_limit=None,
    ) -> None:
        super().__init__(robot, dt=dt, limit_gain=limit_gain, position_limits=position_limits,
                         velocity_limits=velocity_limits, strict=strict,
                         acceleration_limit=acceleration_limit, collisions=collisions,
                         jerk_limit=jerk_limit)
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
        #: how close to its bound a collision row counts as held (m/s): the backend's accuracy
        self._at_bound = max(AT_BOUND, float(self.settings.get("eps_abs", 0.0)))
        self.twist_weight = twist_weight
        self._assembly = TaskAssembly(self.model.nv)
        # proxqp and daqp are called directly (persistent proxqp objects; daqp.solve),
        # the other backends through qpsolvers. Settings a direct call cannot apply
        # send proxqp and daqp back through qpsolvers as well.
        self._proxqp = (ProxQPSolver(self.settings,
                                     frozenset({"eps_abs", "rho", "max_iter"}
                                               - set(user_settings)))
                        if solver == "proxqp" and ProxQPSolver.accepts(self.settings) else None)
        self._direct_daqp = (DirectDAQP(self.settings, user_settings)
                      if solver == "daqp" and DirectDAQP.accepts(self.settings) else None)
        #: what goes through qpsolvers: its proxqp path takes no inner cap (``max_iter_in``)
        self._qpsolvers_settings = {k: v for k, v in self.settings.items()
                                    if not (solver == "proxqp" and k == "max_iter_in")}
        #: OSQP's certified solves past its cap, when the cap and rho are the project's
        self._capped_settings = (OSQP_CAPPED_SETTINGS if solver == "osqp" and not
                                 {"max_iter", "rho", "adaptive_rho"} & set(user_settings)
                                 else ())
        self.set_constraints(constraints)

    def _prepare(self) -> None:
        self._equalities = [i for i, k in enumerate(self.constraints) if k.is_equality]
        self._barriers = [i for i, k in enumerate(self.constraints) if not k.is_equality]
        if self._proxqp is not None:
            self._proxqp.reset()

    # -- the step ----------------------------------------------------------------------

    @property
    def twist_weight(self) -> np.ndarray:
        """Diagonal weight ``W`` of the twist error (task_size,); assign a new one to change
        it (a task mode, docs/design.md section 20)."""
        return self._twist_weight

    @twist_weight.setter
    def twist_weight(self, twist_weight) -> None:
        weight = as_twist_weight(twist_weight, self.task_size)
        self._twist_weight = weight
        self._twist_scale = np.sqrt(weight)
        self._twist_rows = self._twist_scale[:, None]  # W^1/2, to scale the rows of J_e
        self._unit_weight = bool(np.all(weight == 1.0))
        #: the task rows the damping sees: those of non-zero weight, as the CJM's (every
        #: row: a slice, whose view saves the 11k-instruction copy of a fancy index)
        self._weighted_rows: slice | np.ndarray = (
            slice(None) if bool(np.all(weight > 0.0)) else np.flatnonzero(weight > 0.0))

    def posture_velocity(self, q: np.ndarray) -> np.ndarray:
        """``posture_gain * (posture (-) q)`` (nv,): the CJM's posture velocity."""
        if self.posture_gain == 0.0:
            return np.zeros(self.model.nv)
        return self.posture_gain * posture_difference(self.model, q, self.posture,
                                                       self._base_velocity)

    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        self.budget.start()
        self.info.method = f"qp:{self.solver}"
        jacobian = kinematics.ee_jacobian
        A, b = self.constraint_rows(self._equalities) if self._equalities else (None, None)
        collisions = self.collision_rows()
        if collisions is not None:  # measured whatever the solve does
            record_distances(self.info, collisions)
            collisions = braked_pairs(collisions, self.collisions,
                                      self.joint_bounds.acceleration_limit, self.dt)
        barrier_rows, barrier_bound = self._inequality_rows(collisions)
        lower, upper = bounded_box(*self.bounds(kinematics.q))
        weighted_jacobian = jacobian if self._unit_weight else self._twist_rows * jacobian
        damping = task_damping(A, weighted_jacobian[self._weighted_rows], self.policy)
        self.info.sigma_min, self.info.damping = damping.sigma_min, damping.damping
        try:
            qd = self._prioritised(kinematics.q, weighted_jacobian, twist, damping,
                                   A, b, barrier_rows, barrier_bound, lower, upper)
        except SolverError as error:  # infeasible, or out of iterations (proxqp's sign of it)
            if A is None and barrier_rows is None:
                raise
            try:
                held = self._least_residual(A, b, barrier_rows, barrier_bound, lower, upper)
            except SolverError as second:
                raise error from second
            if held.residual > EQUALITY_TOLERANCE:
                self.info.report(StepStatus.CONSTRAINT_DEGRADED, held_note(held.residual))
                if collisions is not None:
                    report_conflict(self.info, collisions,
                                    rows_at_bound(collisions, held.qd, self._at_bound))
            # else the rows fit the limits, but the solver missed them: daqp's "infeasible"
            # where collision rows meet the box beside the trocars' rows in a sliver. Held
            # at the least-residual command's values, the rows are consistent by
            # construction, and the stages run again under them (a stage out of iterations
            # or time still fails the step)
            try:
                qd = self._prioritised(kinematics.q, weighted_jacobian, twist, damping,
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
        if self._barriers:
            count = len(self._barriers)  # one row each, before the collision rows
            held_barriers = np.flatnonzero(barrier_rows[:count] @ qd - barrier_bound[:count]
                                           > -1e-9)
            self.info.active_barriers = tuple(self._barriers[i] for i in held_barriers)
        missed = report_twist_error(self.info, jacobian, qd, twist,
                                    None if self._unit_weight else self._twist_scale)
        if collisions is not None:
            held_pairs = rows_at_bound(collisions, qd, self._at_bound)
            report_held_back(self.info, pair_names(collisions, held_pairs),
                             pair_list(collisions, held_pairs), missed)
        return qd

    def _inequality_rows(self, collisions: CollisionRows | None
                         ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """``G qd <= h``: the barriers' rows, then the ``collisions`` rows
        (``rows qd >= lower`` as ``-rows qd <= -lower``; docs/design.md 18.5), or
        ``(None, None)`` when there is none. Every stage holds them alike. With
        acceleration limits the barriers' bounds are braking-aware (docs/design.md 12; the
        collision rows come braked)."""
        blocks, bounds = [], []
        if self._barriers:
            rows, rhs = self.constraint_rows(self._barriers)
            if self.joint_bounds.acceleration_limit is not None:
                barriers = [self.constraints[i] for i in self._barriers]
                gaps = np.concatenate([c.error(self.data.oMf[self.constraint_frames[i]])
                                       for c, i in zip(barriers, self._barriers)])
                rhs = braked_lower(rows, rhs, gaps, np.array([c.gain for c in barriers]),
                                   self.joint_bounds.acceleration_limit, self.dt)
            blocks.append(-rows)  # A qd >= b as -A qd <= -b
            bounds.append(-rhs)
        if collisions is not None and collisions.size:
            blocks.append(-collisions.rows)
            bounds.append(-collisions.lower)
        if not blocks:
            return None, None
        if len(blocks) == 1:
            return blocks[0], bounds[0]
        return np.vstack(blocks), np.concatenate(bounds)

    def _prioritised(self, q: np.ndarray, weighted_jacobian: np.ndarray, twist: np.ndarray,
                     damping: TaskDamping, A: np.ndarray | None, b: np.ndarray | None,
                     barrier_rows: np.ndarray | None, barrier_bound: np.ndarray | None,
                     lower: np.ndarray | None, upper: np.ndarray | None) -> np.ndarray:
        """The lexicographic (or weighted) solve under the rows ``A qd = b``, the barriers
        ``barrier_rows qd <= barrier_bound`` and the box (docs/design.md section 10).
        ``damping`` carries the damping rows and ``null(A)`` (the same for the rows held by
        the least-residual stage, which span the rows' row space)."""
        nv = self.model.nv
        stacked, stacked_target, hessian, gradient = self._assembly.assemble(
            weighted_jacobian, twist if self._unit_weight else self._twist_scale * twist,
            A, b, damping.rows)
        barrier_lower = None if barrier_rows is None else np.full(barrier_rows.shape[0],
                                                                   -INFINITE_BOUND)
        if self.priorities == "weighted":
            hessian.flat[::nv + 1] += self.mu  # + mu I
            gradient -= self.mu * self.posture_velocity(q)
            return self._solve_stage(QuadraticProgram(
                hessian, gradient, A, b, barrier_rows, barrier_lower, barrier_bound,
                lower, upper, curvature=self.mu), damping.null_basis).x
        geometry = task_geometry(stacked, hessian)
        spare = geometry.null_basis.shape[1] > 0
        task = QuadraticProgram(hessian, gradient, A, b, barrier_rows, barrier_lower,
                                barrier_bound, lower, upper, geometry.curvature, spare)
        stage_1 = self._solve_stage(task, damping.null_basis)
        if not spare:
            return stage_1.x
        return posture_stage(stage_1, geometry.null_basis, self.posture_velocity(q), task,
                             stacked, stacked_target, self._solve_qp,
                             self.settings.get("eps_abs", 0.0))

    def _least_residual(self, A: np.ndarray | None, b: np.ndarray | None,
                        barrier_rows: np.ndarray | None, barrier_bound: np.ndarray | None,
                        lower: np.ndarray | None, upper: np.ndarray | None) -> HeldRows:
        """The rows as close to ``b`` as the box and the barriers allow
        (:mod:`controllers.optimization.least_residual`)."""
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

    # -- backends ----------------------------------------------------------------------

    def _solve_stage(self, problem: QuadraticProgram, null_basis: np.ndarray) -> QPSolution:
        """A stage under the equality rows ``A`` of ``problem`` (``null_basis`` is
        ``null(A)``): over ``null(A)`` where a bounded joint is nearly fixed by them
        (:mod:`controllers.qp.reduced`, docs/design.md 10.2), else as it is."""
        if not nearly_fixed(problem, null_basis):
            return self._solve_qp(problem)
        stage = eliminated(problem, null_basis)
        if not null_basis.shape[1]:  # the rows fix every joint: x_p, checked against the box
            return restored(stage, QPSolution(np.zeros(0), None, None))
        return restored(stage, self._solve_qp(stage.problem))

    def _solve_qp(self, problem: QuadraticProgram) -> QPSolution:
        """``problem`` by the backend: persistent proxqp objects, ``daqp.solve`` directly,
        or qpsolvers for the others (and for settings the direct calls cannot apply)."""
        if self._proxqp is not None:
            return self._proxqp.solve(problem, self.budget)
        if self._direct_daqp is not None:
            return self._direct_daqp.solve(problem, self.budget)
        return solve_with_qpsolvers(problem, self.solver, self._qpsolvers_settings, self.budget,
                                    self._capped_settings)
