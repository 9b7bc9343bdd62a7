"""The Constrained Jacobian Matrix controller: which form solves a step, barriers, limits."""

from __future__ import annotations

import math
from typing import Iterable, Literal

import numpy as np
import pinocchio as pin

from constraints import Constraint, Parametrisation, RobotLike
from constraints.validation import as_number, as_vector

from ..base import Controller, Kinematics, StepStatus, as_twist_weight
from ..joint_limits import DEFAULT_LIMIT_GAIN
from ..linalg import RANK_TOLERANCE, DampingPolicy
from .analytical import (
    ChainSplit,
    SquarePreChain,
    chain_split,
    solve_redundant_pre_chain,
)
from .general import solve_general
from .saturation import rows_scaled_note, saturate_in_null_space

#: A barrier row is violated when the solution undercuts it by more than this (m/s).
BARRIER_TOLERANCE = 1e-12

Form = Literal["auto", "general"]
Backend = Literal["auto", "compiled", "python"]


def compiled_step_available() -> bool:
    """Whether the C++ extension of the compiled step (section 16) is built here."""
    try:
        from ._step import JOINT_KINDS, Pipeline  # noqa: F401  (an older build lacks them)
    except ImportError:
        return False
    return True


def unsupported_joint_kinds(model: pin.Model) -> list[str]:
    """The kinds of ``model``'s joints the compiled step's kinematics does not cover."""
    from ._step import JOINT_KINDS

    return sorted({joint.shortname() for joint in model.joints[1:]} - set(JOINT_KINDS))


class CJMController(Controller):
    """Joint velocities from an EE twist through the Constrained Jacobian Matrix.

    * **Analytical form** (:mod:`controllers.cjm.analytical`): one end effector and one
      equality constraint with at least 6 joints before it, the paper's method (eqs
      17-24, 29-32). For a
      square pre-chain a step is two 6 x 6 LU factorisations into buffers allocated once.
    * **General form** (:mod:`controllers.cjm.general`): several row sets at once (an
      equality and an active barrier, or several constraints), several end effectors
      (their twists stacked: docs/design.md section 11), fewer than 6 joints before the
      constraint, or a singular pre-chain.
    * **Barriers** are held as plane equalities once the solution would break them (an
      active set, most violated first).
    * **Joint limits** (:mod:`controllers.cjm.saturation`): when the command leaves the
      joint box (velocity limits, position limits through ``dt``), saturation in the
      null space; the rows stay hard, the task is scaled, never the constraint unless
      its own correction cannot fit. Where no limit binds the result is the plain form's.

    Parameters
    ----------
    robot : the robot (``model``, ``ee_frame``, ``q_home``).
    constraints : the constraints to hold.
    dt : control period (s), for the position limits.
    damping : constant DLS damping ``lambda`` (paper eq 35); 0 gives the exact inverse.
    singular_threshold, max_damping : the rising damping near singularity
        (:class:`controllers.linalg.DampingPolicy`).
    parametrisation : ``"nullspace"`` (singularity-free, default) or ``"paper"`` (the
        ``1/a`` form of eqs 9-13: holes only; where ``a`` reaches 0 the step falls back
        to the null-space form and says so).
    posture : configuration the redundancy is spent on (default ``robot.q_home``).
    posture_gain : gain (1/s) of the null-space posture task; 0 gives minimum norm.
    form : ``"auto"`` (analytical where it applies) or ``"general"`` (always the
        null-space form: the cross-check).
    twist_weight : diagonal weight ``W`` of the twist error, 6 values for every EE or one
        per entry of the stacked twist (default identity): the task becomes
        ``W^1/2 J_e qd = W^1/2 V_e`` in the general form, as the QP's
        ``|J_e qd - V_e|_W^2``; a zero weight leaves that entry to the posture
        (docs/design.md section 11.2). Anything but the identity takes the general form.
    limit_gain, position_limits, velocity_limits, strict : see
        :class:`controllers.base.Controller`.
    backend : ``"compiled"`` (the whole step in C++, Pinocchio's kinematics included,
        :mod:`controllers.cjm.compiled`, docs/design.md section 16), ``"python"`` (this
        module and its siblings: the readable reference) or ``"auto"`` (compiled when the
        extension is built and covers the robot's joints, else Python). ``"compiled"``
        raises ``ImportError`` without the extension and ``ValueError`` for a robot it
        does not cover. The compiled step computes its kinematics on its own copy of the
        model: it leaves ``self.data`` as it was.
    """

    def __init__(
        self,
        robot: RobotLike,
        constraints: Iterable[Constraint] = (),
        dt: float = 1e-3,
        damping: float = 0.0,
        singular_threshold: float = 0.01,
        max_damping: float = 0.05,
        parametrisation: Parametrisation = "nullspace",
        posture: np.ndarray | None = None,
        posture_gain: float = 1.0,
        form: Form = "auto",
        twist_weight=None,
        limit_gain: float = DEFAULT_LIMIT_GAIN,
        position_limits: bool = True,
        velocity_limits: bool = True,
        strict: bool = False,
        backend: Backend = "auto",
    ) -> None:
        super().__init__(robot, dt=dt, limit_gain=limit_gain, position_limits=position_limits,
                         velocity_limits=velocity_limits, strict=strict)
        if parametrisation not in ("nullspace", "paper"):
            raise ValueError(f"unknown parametrisation {parametrisation!r}: 'nullspace' or 'paper'")
        if form not in ("auto", "general"):
            raise ValueError(f"unknown form {form!r}: 'auto' or 'general'")
        if backend not in ("auto", "compiled", "python"):
            raise ValueError(f"unknown backend {backend!r}: 'auto', 'compiled' or 'python'")
        available = compiled_step_available()
        if backend == "compiled" and not available:
            raise ImportError("the compiled CJM step (controllers.cjm._step) is not built: "
                              "reinstall with pip install -e . (it needs a C++17 compiler)")
        unsupported = unsupported_joint_kinds(self.model) if available else []
        if backend == "compiled" and unsupported:
            raise ValueError(f"the compiled CJM step does not cover joints of kind "
                             f"{', '.join(unsupported)}: use backend='python'")
        #: whether the Python step may stand in when the compiled one cannot take the robot
        self._python_if_needed = backend == "auto"
        if backend == "auto":
            backend = "compiled" if available and not unsupported else "python"
        self.backend: Backend = backend
        self._compiled = None
        self.policy = DampingPolicy(as_number(damping, "damping", 0.0),
                                    as_number(singular_threshold, "singular_threshold", 0.0),
                                    as_number(max_damping, "max_damping", 0.0))
        self.parametrisation: Parametrisation = parametrisation
        self.posture_gain = as_number(posture_gain, "posture_gain", 0.0)
        self.form: Form = form
        self.twist_weight = as_twist_weight(twist_weight, self.task_size)
        #: the task entries asked for (weight > 0: a zero-weight row would read as a
        #: singular direction and bring the damping in), or None for the identity
        self._task_rows = (None if np.all(self.twist_weight == 1.0)
                           else np.flatnonzero(self.twist_weight > 0.0))
        #: W^1/2 of those entries, a column to scale the rows of J_e
        self._task_row_scale = np.sqrt(self.twist_weight if self._task_rows is None
                                       else self.twist_weight[self._task_rows])[:, None]
        if posture is None:
            posture = getattr(robot, "q_home", None)
        self.posture = (pin.neutral(self.model) if posture is None
                        else as_vector(posture, self.model.nq, "posture"))
        self._splits: dict[int, ChainSplit | None] = {}
        self._square_plans: dict[int, SquarePreChain] = {}
        self._active: list[int] = []
        #: joint name per velocity index (a multi-dof joint repeats its name)
        self._joint_names = [self.model.names[j] for j in range(1, self.model.njoints)
                             for _ in range(self.model.nvs[j])]
        self.set_constraints(constraints)

    def _prepare(self) -> None:
        if self.parametrisation == "paper":
            for constraint in self.constraints:
                if not constraint.has_paper_form:
                    raise ValueError(
                        f"parametrisation='paper' does not cover {type(constraint).__name__} "
                        "(its 1/a form needs the constrained directions perpendicular to p "
                        "at every configuration, as a hole's are): use 'nullspace'")
        self._equalities = [i for i, c in enumerate(self.constraints) if c.is_equality]
        self._barriers = [i for i, c in enumerate(self.constraints) if not c.is_equality]
        self._square_plans = {}
        if self.backend == "compiled":
            from .compiled import CompiledStep, KinematicsMismatch

            try:
                self._compiled = CompiledStep(self)
            except KinematicsMismatch:
                if not self._python_if_needed:
                    raise
                self.backend, self._compiled = "python", None

    def solve(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """:meth:`Controller.solve`, in C++ with the compiled backend (section 16)."""
        if self._compiled is None:
            return super().solve(q, twist)
        return self._compiled.solve(q, twist)

    # -- chain structure ---------------------------------------------------------------

    def split(self, frame_id: int) -> ChainSplit | None:
        """Joints before/after the link of ``frame_id`` on the path to the EE (cached)."""
        if frame_id not in self._splits:
            self._splits[frame_id] = chain_split(self.model, frame_id, self.ee_frame_id)
        return self._splits[frame_id]

    def constrained_jacobian(self, q: np.ndarray, index: int = 0) -> np.ndarray:
        """The CJM ``Jbar = [Ad_ea S, J_post]`` of constraint ``index`` at ``q`` (eq 24), for
        the first end effector."""
        q = as_vector(q, self.model.nq, "q")
        self._kinematics(q)
        frame_id = self.constraint_frames[index]
        split = self.split(frame_id)
        if split is None:
            raise ValueError(f"the EE is not downstream of link {self.constraints[index].link!r}")
        placement = self.data.oMf[frame_id]
        structure = self.constraints[index].structure(placement, self.parametrisation)
        ad_ea = self.data.oMf[self.ee_frame_id].actInv(placement).action
        ee_jacobian = pin.getFrameJacobian(self.model, self.data, self.ee_frame_id, pin.LOCAL)
        return np.hstack([ad_ea @ structure, ee_jacobian[:, split.post]])

    # -- the step ----------------------------------------------------------------------

    def _kinematics(self, q: np.ndarray) -> Kinematics:
        """The base's kinematics, with the task Jacobian ``W^1/2 J_e`` (the rows of
        non-zero weight) when weighted."""
        kinematics = super()._kinematics(q)
        kinematics.ee_jacobian = self._task_jacobian(kinematics.ee_jacobian)
        return kinematics

    @property
    def task_rows(self) -> int:
        """Rows of the task the forms solve: 6 per EE, or those of non-zero weight."""
        return self.task_size if self._task_rows is None else self._task_rows.size

    @property
    def paper_task(self) -> bool:
        """One EE and its full, unweighted twist: the task of the analytical form."""
        return self.task_size == 6 and self._task_rows is None

    def _task_jacobian(self, ee_jacobian: np.ndarray) -> np.ndarray:
        """``W^1/2 J_e`` (the rows of non-zero weight) from the stacked EE Jacobians."""
        if self._task_rows is None:
            return ee_jacobian
        return self._task_row_scale * ee_jacobian[self._task_rows]

    def _task(self, twist: np.ndarray) -> np.ndarray:
        """``W^1/2 V_e``: the twist the weighted task Jacobian must meet."""
        if self._task_rows is None:
            return twist
        return self._task_row_scale[:, 0] * twist[self._task_rows]

    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        twist = self._task(twist)
        self._active = list(self._equalities)
        qd = self._solve_rows(kinematics, twist, self._active)
        if self._barriers:
            qd = self._activate_barriers(kinematics, twist, qd)
        return qd

    def _activate_barriers(self, kinematics: Kinematics, twist: np.ndarray,
                           qd: np.ndarray) -> np.ndarray:
        """Active set over the barriers: hold the most violated one as an equality, again."""
        waiting = [i for i in self._barriers if i not in self._active]
        while waiting:
            violations = []
            for i in waiting:
                rows, rhs = self.constraints[i].rows(self.model, self.data, self.constraint_frames[i])
                violations.append(float(rhs[0] - rows[0] @ qd))
            worst = int(np.argmax(violations))
            if violations[worst] <= BARRIER_TOLERANCE:
                break
            self._active.append(waiting.pop(worst))
            qd = self._solve_rows(kinematics, twist, self._active)
        self.info.active_barriers = tuple(i for i in self._active if i in self._barriers)
        return qd

    def _solve_rows(self, kinematics: Kinematics, twist: np.ndarray, active: list[int]) -> np.ndarray:
        """The analytical form where it applies, else the general form, for these rows."""
        if len(active) == 1 and self.form == "auto" and self.paper_task:
            qd = self._solve_analytical(kinematics, twist, active[0])
            if qd is not None:
                return qd
        rows, rows_rhs = self.constraint_rows(active)
        return solve_general(rows, rows_rhs, kinematics.ee_jacobian, twist, self.policy,
                             self._posture_velocity(kinematics.q), self.info)

    def _solve_analytical(self, kinematics: Kinematics, twist: np.ndarray, index: int) -> np.ndarray | None:
        """The analytical form of constraint ``index``, or None where it does not apply;
        the joints off the path to the EE (they move neither the task nor the constraint:
        columns of zeros in ``J_e`` and ``A``) take the posture velocity, as in the
        general form, where they lie in ``null(A)`` and ``null(J_e N)``."""
        qd = self._solve_analytical_path(kinematics, twist, index)
        if qd is not None and self.posture_gain > 0.0:
            off = self.split(self.constraint_frames[index]).off
            if off.size:
                qd[off] = self._posture_velocity(kinematics.q)[off]
        return qd

    def _solve_analytical_path(self, kinematics: Kinematics, twist: np.ndarray,
                               index: int) -> np.ndarray | None:
        """The analytical form over the joints on the path to the EE (zero elsewhere)."""
        frame_id = self.constraint_frames[index]
        if (self.parametrisation == "paper"
                and not self._paper_form_defined(index, self.data.oMf[frame_id])):
            self.info.report(StepStatus.OK, "a = 0, where the paper's 1/a form is singular: "
                                            "null-space form used")
            return None
        plan = self._square_plans.get(index)  # the paper's case, seen before
        if plan is None:
            split = self.split(frame_id)
            if split is None or split.pre.size < 6:
                return None
            if split.pre.size > 6:
                return solve_redundant_pre_chain(
                    self.model, self.data, kinematics.ee_jacobian, kinematics.ee_placement,
                    self.constraints[index], frame_id, split, twist, self.policy,
                    self.parametrisation, self._posture_velocity(kinematics.q), self.info)
            plan = self._square_plans[index] = SquarePreChain(
                self.constraints[index], frame_id, self.model.nv, split, self.parametrisation)
        return plan.solve(self.model, self.data, kinematics.ee_jacobian, twist, self.policy, self.info,
                          None if plan.square else self._posture_velocity(kinematics.q))

    def _paper_form_defined(self, index: int, placement: pin.SE3) -> bool:
        """Whether the paper's ``1/a`` structure matrix exists at this placement of
        constraint ``index``'s link (``a = |p|`` not ~0)."""
        return float(np.linalg.norm(self.constraints[index].point(placement))) >= 1e-6

    def _posture_velocity(self, q: np.ndarray) -> np.ndarray | None:
        if self.posture_gain == 0.0:
            return None
        return self.posture_gain * self.posture_difference(q, self.posture)

    # -- joint limits ------------------------------------------------------------------

    def _saturate(self, kinematics: Kinematics, twist: np.ndarray, qd: np.ndarray,
                  lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """Saturation in the null space (module :mod:`controllers.cjm.saturation`)."""
        twist = self._task(twist)
        info = self.info
        for _ in range(len(self._barriers) + 1):
            rows, rows_rhs = self.constraint_rows(self._active)
            result = saturate_in_null_space(rows, rows_rhs, kinematics.ee_jacobian, twist,
                                            lower, upper, self.velocity_limit, self.policy)
            waiting = [i for i in self._barriers if i not in self._active]
            violated = [i for i in waiting if self._barrier_violation(i, result.qd) > BARRIER_TOLERANCE]
            if not violated:
                break
            self._active.append(max(violated, key=lambda i: self._barrier_violation(i, result.qd)))
        info.active_barriers = tuple(i for i in self._active if i in self._barriers)
        info.method = "saturated"
        info.scale = result.task_scale
        info.saturated_joints = result.saturated
        if not math.isnan(result.sigma_min):  # the task's DLS that gave this command
            info.sigma_min, info.damping = result.sigma_min, result.damping
        info.equality_residual = (float(np.max(np.abs(rows @ result.qd - rows_rhs)))
                                  if rows.shape[0] else 0.0)
        if result.rows_scale < 1.0:
            info.report(StepStatus.CONSTRAINT_DEGRADED, rows_scaled_note(result.rows_scale))
        elif result.task_missed:
            info.report(StepStatus.LEAST_SQUARES,
                        self._task_missed_note(result.saturated, result.sigma_min, result.damping))
        elif result.task_scale < 1.0:
            info.report(StepStatus.SCALED,
                        self._task_scaled_note(result.limiting_joint, result.task_scale))
        return result.qd

    def _task_missed_note(self, saturated: Iterable[int], sigma_min: float, damping: float) -> str:
        """What keeps a saturated step from the task: the joints held at a limit, the
        damping near a singularity (eq 35), else a least-squares task (rank lost)."""
        saturated = list(saturated)
        causes = [f"{self._joint_list(saturated)} at a limit"] if saturated else []
        # below the rank cut sigma_min is rounding: 0 (the two backends round differently)
        sigma = f"sigma_min {sigma_min if sigma_min > RANK_TOLERANCE else 0.0:.2g}"
        if damping > 0.0:
            causes.append(f"near a singularity ({sigma}, damping {damping:.2g})")
        if not causes:
            causes.append(f"least squares ({sigma})")
        return f"{'; '.join(causes)}: task not fully achievable"

    def _task_scaled_note(self, joint: int, scale: float) -> str:
        limit = f"{self._joint_list([joint])} at a limit" if joint >= 0 else "the joint limits"
        return f"{limit}: task scaled to {scale:.0%}"

    def _joint_list(self, velocity_indices: Iterable[int]) -> str:
        """``joint arm_joint_4`` / ``joints a, b`` for velocity indices (a multi-dof
        joint named once)."""
        names = list(dict.fromkeys(self._joint_names[i] for i in velocity_indices))
        return f"joint{'s' if len(names) > 1 else ''} {', '.join(names)}"

    def _barrier_violation(self, index: int, qd: np.ndarray) -> float:
        rows, rhs = self.constraints[index].rows(self.model, self.data, self.constraint_frames[index])
        return float(rhs[0] - rows[0] @ qd)
