"""The constrained teleoperation step solved by mink's ``solve_ik`` (docs/design.md 4.8)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import mink
import mujoco
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
from ..mujoco_model import build_mujoco_model, site_name
from ..numerics import INFINITE_BOUND
from ..optimization.budget import BudgetExceeded, StepBudget, TimeBudget
from ..optimization.collision_report import (AT_BOUND, describe_pair, record_distances,
                                             report_conflict, report_held_back, rows_at_bound)
from ..optimization.least_residual import HeldRows, held_note, held_rows, least_residual_problem
from ..optimization.task_damping import task_damping
from .adapters import BarrierLimit, ConstraintTask, DampingTask, PostureTask
from .acceleration_limit import AccelerationLimit
from .collision_limit import CollisionPairsLimit, CollisionScene
from .joint_box import JointBoxLimit
from .rows import PinocchioRows, RowsCache
from .backend import MinkBackend
from .settings import DEFAULT_DAMPING, DEFAULT_POSTURE_COST, VELOCITY_TOLERANCES

#: Pinocchio's ``[x y z qx qy qz qw]`` re-ordered into mink's ``wxyz_xyz``.
_WXYZ_XYZ = np.array([6, 3, 4, 5, 0, 1, 2])

LimitSpec = mink.Limit | Callable[[mujoco.MjModel], mink.Limit]


class MinkController(GuardedController):
    """The constrained teleoperation step solved by mink's ``solve_ik``.

    Per step, with ``T_e`` the EE pose and ``V`` the desired EE body twist (several EEs:
    one FrameTask each, ``V_i`` the ``i``-th 6 entries of the stacked twist, and the
    first term summed over them; docs/design.md section 11)::

        target  = T_e exp6(V dt)                    FrameTask on the EE site (cost 1, 1)
        min_dq  |Jlog(T_t^-1 T_e) (J_e dq - V dt)|^2 + c^2 |dq - qd_posture dt|^2 + damping |dq|^2
        s.t.    A dq = b dt                         ConstraintTask per equality (hard)
                -A_b dq <= -b_b dt                  BarrierLimit per barrier
                lower dt <= dq <= upper dt          JointBoxLimit (JointBounds.box(q))
                -d_dot dt <= k dt^2 (d - d_s) / dt  CollisionPairsLimit, per pair within d_i
        qd = dq / dt                                (solve_ik's return value)

    **Why this tracks V exactly.** mink's frame error is ``e = log(T_e^-1 T_t) = V dt``
    (for ``|V dt|`` below pi) and its Jacobian ``J = -Jlog(exp(-V dt)) J_e``, so the
    task row ``J dq = -e`` reads ``Jr^-1(-V dt) J_e dq = V dt``. Since
    ``Jr^-1(-x) x = x`` on SE(3) (``ad_x x = 0``), its solution is ``J_e dq = V dt``,
    i.e. ``J_e qd = V``: whenever the constrained task is feasible (6 + k = n, the
    built-in robots with a hole), mink's ``qd`` is the CJM's. When it is not (e.g. a
    barrier is active) mink minimises ``|J_e qd - V|`` in the metric
    ``W = Jr^-1(-V dt) = I + O(|V dt|)`` instead of the QP controller's identity:
    the two least-squares answers then differ by ``O(|V dt|)`` relative.

    **Accuracy floor.** mink 1.3.0 evaluates ``Jlog`` (``mink/lie/se3.py::_getQ``) with
    ``(1 - t^2/2 - cos t) / t^4`` and a similar quintic term in closed form once ``t^2``
    exceeds machine epsilon; at ``t = |w| dt`` of a teleoperation step the cancellation
    leaves ``Jlog`` wrong well above rounding, which sets how closely ``J_e qd`` meets
    ``V`` and ``qd`` the CJM's, for every backend (docs/design.md 10.3, tests/test_mink.py).

    **Posture.** A :class:`PostureTask` towards ``posture`` with gain
    ``posture_gain * dt`` (mink's gain is per step) asks for the CJM's and the QP
    controller's posture velocity ``qd_posture = posture_gain * pin.difference(q,
    posture)``. mink sums its tasks, so the posture's cost ``c`` trades the twist for the
    posture by about ``c^2 / sigma^2`` (``sigma`` the task's singular values): the QP
    controller's weighted formulation with ``mu s = c^2``, never its lexicographic one.
    The default cost is about as small as mink's solve still resolves the posture with:
    docs/design.md section 10 gives the deviation from the CJM that remains.

    **Equalities.** Every equality constraint (``is_equality``: a hole, a plane, a point
    lock) is a :class:`ConstraintTask` in ``solve_ik(..., constraints=...)`` and every
    one-sided one (a barrier) is :class:`BarrierLimit` rows; both evaluate the constraints' own ``rows`` with
    Pinocchio at mink's configuration (joints mapped by name). After the solve the rows
    are checked: ``info.equality_residual = max |A qd - b|``, and a residual above
    ``equality_tolerance`` (infeasible equalities that a backend answered in the least
    squares sense) is a failure like a ``NoSolutionFound``: a flagged zero command.

    Parameters
    ----------
    robot : a ``teleop.Robot`` (``urdf_path``, ``model``, ``ee_frames``, ...). The MuJoCo
        model is compiled from the same URDF (geometry dropped), with a site at every
        Pinocchio link frame (``site_name(link)``, the constraint links among them) and
        at every EE frame. Joints must be 1-dof revolute/prismatic, matched by name, on
        a fixed base or on a planar root joint (:func:`build_mujoco_model`).
    constraints, strict, acceleration_limit : see :class:`controllers.base.Controller`
        (the acceleration box is :class:`controllers.mink.acceleration_limit.AccelerationLimit`).
    collisions : the pairs kept apart (:class:`constraints.collision.CollisionAvoidance`),
        posed to mink as its own ``CollisionAvoidanceLimit`` on geoms of the same shapes
        in its MuJoCo model, ``gain = k dt^2`` (the damper's rate ``k``), obstacles as
        world geoms posed each step (:mod:`controllers.mink.collision_limit`,
        docs/design.md 18.5); ``info``'s distances are the avoidance's own.
    solver : any qpsolvers backend mink accepts: ``"daqp"`` (default), ``"proxqp"``,
        ``"osqp"``, ...
    dt : control period (s): mink's integration step.
    damping : mink's Levenberg-Marquardt damping (on ``dq``; acts as ``mu`` on ``qd``).
        Default: 0 with a posture task, :data:`DEFAULT_DAMPING` without.
    posture : configuration the redundancy is spent on (default ``robot.q_home``), as the
        CJM's.
    posture_gain : gain (1/s) of the posture velocity, as the CJM's (at most ``1 / dt``:
        mink's per-step gain is ``posture_gain * dt`` and must not exceed 1).
    posture_cost : the posture task's cost relative to the task's scale: mink's cost is
        ``c = posture_cost * sqrt(s)``, ``s = |W^1/2 J_e|_F^2 / m`` (``J_e`` stacked,
        ``m = 6`` rows per EE: the mean squared singular value, as the QP controller's
        ``s``), set every step (0: no posture task). With proxqp, its ``rho`` follows as
        ``PROXQP_RHO c^2`` (:mod:`controllers.numerics`): proxqp's own 1e-6 is far too
        large against that curvature (docs/design.md 10.2).
    limits : ``None`` for the default, the controller's joint box
        (:class:`controllers.mink.joint_box.JointBoxLimit`: velocity limits, and position
        limits through ``dt`` with ``limit_gain``, on Pinocchio's velocity, a planar base's
        in its own frame; docs/design.md 10.7),
        else a sequence of ``mink.Limit`` instances or factories ``f(mj_model) -> Limit``
        (``mink.ConfigurationLimit`` itself is one); ``()`` for none. The one-sided
        constraints' limits are always added.
    limit_gain : ``g`` of the joint box (:class:`controllers.joint_limits.JointBounds`).
    equality_tolerance : largest ``|A qd - b|`` (m/s) accepted from the backend.
    solver_settings : backend keyword arguments, passed as they are (they override the
        defaults built from ``VELOCITY_TOLERANCES`` and ``FIXED_SETTINGS``).
    twist_weight : the diagonal ``W`` of the CJM's and the QP's weighted task: each frame
        task's position and orientation costs are ``W^1/2`` of its EE's entries.
    time_budget, singular_threshold, max_damping : the step's deadline and the CJM's
        damping policy, as :class:`controllers.QPController`'s (docs/design.md 10.6, 10.7).
    """

    def __init__(
        self,
        robot,
        constraints: Iterable[Constraint] = (),
        solver: str = "daqp",
        dt: float = 1e-3,
        damping: float | None = None,
        posture: np.ndarray | None = None,
        posture_gain: float = 1.0,
        posture_cost: float = DEFAULT_POSTURE_COST,
        limits: Sequence[LimitSpec] | None = None,
        limit_gain: float = DEFAULT_LIMIT_GAIN,
        equality_tolerance: float = 1e-6,
        solver_settings: dict | None = None,
        twist_weight=None,
        time_budget: TimeBudget = "periods",
        singular_threshold: float = 0.01,
        max_damping: float = 0.05,
        strict: bool = False,
        acceleration_limit=None,
        collisions: CollisionAvoidance | None = None,
        jerk_limit=None,
    ) -> None:
        super().__init__(robot, dt=dt, limit_gain=limit_gain, strict=strict,
                         acceleration_limit=acceleration_limit, collisions=collisions,
                         jerk_limit=jerk_limit)
        self.budget = StepBudget(time_budget, self.dt)
        self.policy = DampingPolicy(0.0, as_number(singular_threshold, "singular_threshold", 0.0),
                                    as_number(max_damping, "max_damping", 0.0))
        self.ee_tasks: list[mink.FrameTask] = []
        self.twist_weight = twist_weight
        if solver not in qpsolvers.available_solvers:
            raise ValueError(
                f"QP solver {solver!r} is not available to mink; installed: "
                f"{qpsolvers.available_solvers}")
        self.posture_gain = as_number(posture_gain, "posture_gain", 0.0, maximum=1.0 / self.dt)
        self.posture_cost = as_number(posture_cost, "posture_cost", 0.0)
        if damping is None:
            damping = 0.0 if self.posture_cost > 0.0 else DEFAULT_DAMPING
        self.damping = as_number(damping, "damping", 0.0)
        self.equality_tolerance = as_number(equality_tolerance, "equality_tolerance", positive=True)
        self.solver = solver
        self.backend = MinkBackend(solver, self.dt, self.posture_cost, solver_settings,
                                   self.budget)
        #: the backend's settings (one dict: changing it changes the next solve)
        self.settings = self.backend.settings
        #: how close to its bound a collision row counts as held (m/s): the backend's accuracy
        self._at_bound = max([AT_BOUND, *VELOCITY_TOLERANCES.get(solver, {}).values()])

        # The MuJoCo side, built before the constraints that use it (and again when the
        # collision avoidance or its obstacles' shapes change).
        model: pin.Model = robot.model
        ee_frames = [model.frames[frame_id].name for frame_id in self.ee_frame_ids]
        frames = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
        frames.extend(ee_frames)
        self._frames, self._ee_frames, self._limit_specs = frames, ee_frames, limits
        self.site_names = {name: site_name(name) for name in frames}
        self.ee_site = site_name(ee_frames[0])
        #: the avoidance's shapes in the MuJoCo model, its pairs as mink's collision limit
        #: (None without collision avoidance; docs/design.md 18.5)
        self._scene: CollisionScene | None = None
        self.collision_limit: CollisionPairsLimit | None = None
        self._build_mujoco()
        #: one frame task per end effector, in ``robot.ee_frames`` order
        self.ee_tasks = [mink.FrameTask(site_name(name), "site",
                                        position_cost=self._twist_scale[6 * i:6 * i + 3],
                                        orientation_cost=self._twist_scale[6 * i + 3:6 * i + 6],
                                        gain=1.0, lm_damping=0.0)
                         for i, name in enumerate(ee_frames)]
        #: the default limit, the controller's joint box (None with ``limits`` given)
        self._joint_box = (JointBoxLimit(self.joint_bounds, self.joints, model.nq)
                           if limits is None else None)
        #: the acceleration box (None without acceleration limits), whatever ``limits``
        self.acceleration_box = (AccelerationLimit(self.joint_bounds, self.joints, model.nq,
                                                   self.command_box.previous_command,
                                                   self.command_box.jerk_reference)
                                 if self.joint_bounds.acceleration_step is not None else None)
        #: the limits that bound mink's variable directly (their 1-dof joints' part)
        self._variable_bounds = tuple(limit for limit in (self._joint_box, self.acceleration_box)
                                      if limit is not None)
        self._base_limits = self._make_limits(limits)
        if self.acceleration_box is not None:
            self._base_limits.append(self.acceleration_box)
        if posture is None:
            posture = robot.q_home
        self.posture = as_vector(posture, model.nq, "posture")
        self.posture_task = PostureTask(model, self.joints, self.posture, cost=self.posture_cost,
                                        gain=self.posture_gain * self.dt,
                                        difference=functools.partial(
                                            posture_difference, model,
                                            free=self._base_velocity))
        self._tasks = [*self.ee_tasks, self.posture_task] if self.posture_cost else self.ee_tasks
        self.damping_task = DampingTask(self.task_size, self.mj_model.nv)
        self._equality_caches: list[RowsCache] = []
        self.constraint_tasks: list[ConstraintTask] = []
        self.barrier_limits: list[BarrierLimit] = []
        self._limits: list[mink.Limit] = list(self._base_limits)
        self.set_constraints(constraints)

    @property
    def twist_weight(self) -> np.ndarray:
        """Diagonal weight ``W`` of the twist error (task_size,); assign a new one to change
        it (a task mode, docs/design.md section 20): each frame task's costs follow."""
        return self._twist_weight

    @twist_weight.setter
    def twist_weight(self, twist_weight) -> None:
        weight = as_twist_weight(twist_weight, self.task_size)
        self._twist_weight = weight
        self._twist_scale = np.sqrt(weight)  # W^1/2: each frame task's costs
        self._twist_rows = self._twist_scale[:, None]  # W^1/2, to scale the rows of J_e
        self._unit_weight = bool(np.all(weight == 1.0))
        #: the task rows the damping sees: those of non-zero weight, as the CJM's (every
        #: row: a slice, whose view saves the 11k-instruction copy of a fancy index)
        self._weighted_rows: slice | np.ndarray = (
            slice(None) if bool(np.all(weight > 0.0)) else np.flatnonzero(weight > 0.0))
        for i, task in enumerate(self.ee_tasks):
            task.set_position_cost(self._twist_scale[6 * i:6 * i + 3])
            task.set_orientation_cost(self._twist_scale[6 * i + 3:6 * i + 6])

    def _build_mujoco(self) -> None:
        """The MuJoCo model (with the avoidance's shapes, :class:`CollisionScene`), its
        joint map, mink's configuration and the collision limit."""
        robot: Any = self.robot  # a teleop.Robot: its collision model and URDF too
        self._scene = (None if self.collisions is None
                       else CollisionScene(self.collisions, robot.collision_model, self.model))
        self.mj_model, self.joints = build_mujoco_model(
            self.model, robot.urdf_path.read_text(), self._frames,
            getattr(robot, "locked_joints", None),
            None if self._scene is None else self._scene.geometry())
        self.configuration = mink.Configuration(self.mj_model)
        self._ee_site_ids = [self.mj_model.site(site_name(name)).id for name in self._ee_frames]
        self._q_mj = np.empty(self.mj_model.nq)
        self.collision_limit = (None if self._scene is None
                                else self._scene.limit(self.mj_model, self.dt))
        if self.collision_limit is not None and self.joint_bounds.acceleration_limit is not None:
            self.collision_limit.braking = self._braked_collision_bound

    def _rebuild_mujoco(self) -> None:
        """:meth:`_build_mujoco` again, and the limits made on the model."""
        self._build_mujoco()
        self._base_limits = self._make_limits(self._limit_specs)
        if self.acceleration_box is not None:
            self._base_limits.append(self.acceleration_box)

    def _make_limits(self, limits: Sequence[LimitSpec] | None) -> list[mink.Limit]:
        if limits is None:
            return [self._joint_box]
        made = []
        for limit in limits:
            made.append(limit if isinstance(limit, mink.Limit) else limit(self.mj_model))
            if not isinstance(made[-1], mink.Limit):
                raise TypeError(f"limits: expected mink.Limit or a factory of one, got {limit!r}")
        return made

    def _prepare(self) -> None:
        if (self._scene is None) != (self.collisions is None) or (
                self._scene is not None and self._scene.collisions is not self.collisions):
            self._rebuild_mujoco()
        rows = PinocchioRows(self.model, self.data, self.joints, self.mj_model.nq,
                             self.joint_bounds.acceleration_limit, self.dt)
        self._rows = rows
        caches = [RowsCache(c, f, rows) for c, f in zip(self.constraints, self.constraint_frames)]
        self._equality_caches = [c for c in caches if c.constraint.is_equality]
        self.constraint_tasks = [ConstraintTask(c, self.dt) for c in self._equality_caches]
        self.barrier_limits = [BarrierLimit(c) for c in caches if not c.constraint.is_equality]
        self._assemble_limits()

    def _assemble_limits(self) -> None:
        self._limits = [*self._base_limits, *self.barrier_limits,
                        *(() if self.collision_limit is None else (self.collision_limit,))]

    # -- the step ----------------------------------------------------------------------

    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        if self._scene is not None:
            if self._scene.changed():  # obstacles added, removed or reshaped
                self._rebuild_mujoco()
                self._assemble_limits()
            self._scene.place_obstacles(self.mj_model)
        collisions = self.collision_rows()
        if collisions is not None:  # measured whatever the solve does
            record_distances(self.info, collisions)
            collisions = braked_pairs(collisions, self.collisions,
                                      self.joint_bounds.acceleration_limit, self.dt)
        configuration = self.configuration
        q_mj = self.joints.q_to_mujoco(kinematics.q, out=self._q_mj)
        configuration.update(q_mj)
        self._rows.mark_current(q_mj)  # the base class ran Pinocchio at this q already
        data = configuration.data
        dt = self.dt
        for index, (task, site_id) in enumerate(zip(self.ee_tasks, self._ee_site_ids)):
            ee = pin.SE3(data.site_xmat[site_id].reshape(3, 3), data.site_xpos[site_id])
            xyz_quat = pin.SE3ToXYZQUAT(ee * pin.exp6(twist[6 * index:6 * index + 6] * dt))
            # (the attribute set_target would set, without its defensive copy)
            task.transform_target_to_world = mink.SE3(wxyz_xyz=xyz_quat[_WXYZ_XYZ])
        self.info.method = f"mink:{self.solver}"
        if self.posture_cost > 0.0:  # c = posture_cost * sqrt(s), s the task's scale
            cost = self.posture_cost * math.sqrt(
                float(np.vdot(self.twist_weight, np.square(kinematics.ee_jacobian).sum(axis=1)))
                / self.task_size)
            self.posture_task.cost[:] = cost  # (set_cost, without its checks)
            self.backend.set_posture_cost(cost)
        self.budget.start()
        A, b = self._equality_rows()
        damping = task_damping(A, (self._twist_rows * kinematics.ee_jacobian)[self._weighted_rows],
                               self.policy)
        self.info.sigma_min, self.info.damping = damping.sigma_min, damping.damping
        tasks = self._tasks
        if damping.rows.shape[0]:
            self.damping_task.set_rows(self.joints.columns_to_mujoco(damping.rows, q_mj))
            tasks = [*tasks, self.damping_task]
        try:
            qd = self._solve_rows(tasks, q_mj)
        except SolverError as error:  # infeasible rows, or a budget spent
            if not (self._equality_caches or self.barrier_limits or self.collision_limit):
                raise
            try:
                held = self._least_residual(A, b, kinematics.q, collisions)
            except SolverError as second:
                raise error from second
            if held.residual <= EQUALITY_TOLERANCE:
                raise  # the rows fit the limits: the failure was something else
            self.info.report(StepStatus.CONSTRAINT_DEGRADED, held_note(held.residual))
            if collisions is not None:
                report_conflict(self.info, collisions,
                                rows_at_bound(collisions, held.qd, self._at_bound))
            self._hold(held, q_mj)
            try:
                qd = self._solve_rows(tasks, q_mj)
            except BudgetExceeded:
                raise
            except SolverError as task_error:  # (proxqp: a false infeasibility, in dq units)
                qd = held.qd
                self.info.report(StepStatus.LEAST_SQUARES, f"mink under the held rows failed "
                                 f"({task_error}): the least-residual command")
            finally:
                self._hold(None, q_mj)
        if A is not None:
            self.info.equality_residual = float(np.max(np.abs(A @ qd - b)))
        if self.barrier_limits:
            active = []
            for index, limit in zip(
                    (i for i, c in enumerate(self.constraints) if not c.is_equality),
                    self.barrier_limits):
                rows = limit.cache.at(configuration)
                if np.any(rows.A_pin @ qd - rows.b < 1e-9):
                    active.append(index)
            self.info.active_barriers = tuple(active)
        missed = report_twist_error(self.info, kinematics.ee_jacobian, qd, twist,
                                    None if self._unit_weight else self._twist_scale)
        if collisions is not None:
            names = self._held_pairs(qd, q_mj)
            report_held_back(self.info, names, ", ".join(
                describe_pair(collisions, name) for name in names), missed)
        return qd

    def _braked_collision_bound(self, G: np.ndarray, h: np.ndarray, q_mj: np.ndarray
                                ) -> np.ndarray:
        """mink's collision bounds ``G dq <= h`` (``h = k dt (d - d_s)``, 0 at or below
        ``d_s``, inf beyond ``d_i``) made braking-aware: the rows ``-G v >= -h / dt``
        on the Pinocchio velocity ``v`` through :func:`braked_lower` (docs/design.md 12)."""
        near = np.flatnonzero(np.isfinite(h) & (h > 0.0))
        if not near.size:
            return h
        dt, rate = self.dt, self.collisions.gain
        to_mujoco = np.column_stack([self.joints.v_to_mujoco(column, q_mj)
                                     for column in np.eye(self.model.nv)])
        rows = -G[near] @ to_mujoco
        braked = h.copy()
        braked[near] = -dt * braked_lower(rows, -h[near] / dt, h[near] / (rate * dt),
                                          np.full(near.size, rate),
                                          self.joint_bounds.acceleration_limit, dt)
        return braked

    def _held_pairs(self, qd: np.ndarray, q_mj: np.ndarray) -> tuple[str, ...]:
        """The pairs whose rows of mink's collision limit ``qd`` holds at their bound
        (to the backend's accuracy), each named once."""
        rows = self.collision_limit.last
        if rows is None or rows.G is None:
            return ()
        displacement = self.joints.v_to_mujoco(qd, q_mj) * self.dt
        near = np.flatnonzero(np.isfinite(rows.h))
        slack = rows.h[near] - rows.G[near] @ displacement
        held = near[slack <= self._at_bound * self.dt]
        return tuple(dict.fromkeys(self.collision_limit.names[i] for i in held.tolist()))

    def _solve_rows(self, tasks: Sequence[mink.Task], q_mj: np.ndarray) -> np.ndarray:
        """mink's ``qd`` (Pinocchio order) under the rows as the constraint tasks hold them
        (``b``, or the least residual's), which it must meet to ``equality_tolerance``."""
        v_mj = self.backend.solve_ik(self.configuration, tasks, self.damping, self._limits,
                                     self.constraint_tasks, self._variable_bounds)
        if not np.all(np.isfinite(v_mj)):
            raise SolverError(f"mink.solve_ik with solver {self.solver!r} returned a "
                              "non-finite velocity")
        qd = self.joints.v_to_pinocchio(v_mj, q_mj)
        if self._equality_caches:
            residual = max(float(np.max(np.abs(
                task.cache.A_pin @ qd - (task.cache.b if task.held_rhs is None else task.held_rhs))))
                for task in self.constraint_tasks)
            if not residual <= self.equality_tolerance:  # daqp's eq_reduction: least squares
                raise SolverError(
                    f"mink.solve_ik with solver {self.solver!r} returned a velocity that "
                    f"breaks the equality rows by {residual:.3g} m/s (tolerance "
                    f"{self.equality_tolerance:g}): infeasible constraints or an "
                    "inaccurate solve")
        return qd

    def _equality_rows(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The equality rows ``A qd = b`` at the current configuration (Pinocchio order)."""
        if not self._equality_caches:
            return None, None
        caches = [cache.at(self.configuration) for cache in self._equality_caches]
        return np.vstack([c.A_pin for c in caches]), np.concatenate([c.b for c in caches])

    def _least_residual(self, A: np.ndarray | None, b: np.ndarray | None,
                        q: np.ndarray, collisions: CollisionRows | None) -> HeldRows:
        """The rows as close to ``b`` as the box, the barriers and the avoidance's
        collision rows allow (:mod:`controllers.optimization.least_residual`), solved
        with this controller's backend."""
        lower, upper = self.bounds(q)
        lower = np.where(np.isfinite(lower), lower, -INFINITE_BOUND)
        upper = np.where(np.isfinite(upper), upper, INFINITE_BOUND)
        blocks, bounds = [], []
        if self.barrier_limits:
            caches = [limit.cache.at(self.configuration) for limit in self.barrier_limits]
            blocks.append(-np.vstack([c.A_pin for c in caches]))
            bounds.append(-np.concatenate([c.b for c in caches]))
        if collisions is not None and collisions.size:
            blocks.append(-collisions.rows)
            bounds.append(-collisions.lower)
        G = np.vstack(blocks) if blocks else None
        h = np.concatenate(bounds) if bounds else None
        problem = least_residual_problem(A, b, G, h, lower, upper, INFINITE_BOUND)
        return held_rows(self.backend.least_residual(problem), A, b, G, h, lower, upper)

    def _hold(self, held: HeldRows | None, q_mj: np.ndarray) -> None:
        """Make the constraint tasks, barrier limits and the collision limit hold
        ``held``'s rows (None: their own); the collision limit's bounds are raised to
        what the least-residual command reaches on mink's own rows."""
        if held is None:
            for task in self.constraint_tasks:
                task.held_rhs = None
            for limit in self.barrier_limits:
                limit.held_rhs = None
            if self.collision_limit is not None:
                self.collision_limit.held_bound = None
            return
        for task in self.constraint_tasks:
            task.held_rhs = task.cache.A_pin @ held.qd
        for limit in self.barrier_limits:
            limit.held_rhs = np.minimum(limit.cache.b, limit.cache.A_pin @ held.qd)
        rows = None if self.collision_limit is None else self.collision_limit.last
        if rows is not None and rows.G is not None:
            self.collision_limit.held_bound = rows.G @ (
                self.joints.v_to_mujoco(held.qd, q_mj) * self.dt)

    def site_pose(self, frame: str) -> pin.SE3:
        """World pose of the MuJoCo site at Pinocchio frame ``frame`` (last ``solve``'s q)."""
        sid = self.mj_model.site(site_name(frame)).id
        data = self.configuration.data
        return pin.SE3(data.site_xmat[sid].reshape(3, 3).copy(), data.site_xpos[sid].copy())
