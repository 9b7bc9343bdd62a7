"""The Constrained Jacobian Matrix controller: its options, its step setup, its backend."""

from __future__ import annotations

import os
import warnings
from functools import cache, partial
from typing import TYPE_CHECKING, Iterable, Literal, Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint, Parametrisation, RobotLike
from constraints.collision import CollisionAvoidance
from constraints.validation import as_number, as_vector

from ..base import (Controller, Kinematics, SolveInfo, SolverError, StepStatus,
                    as_twist_weight, velocity_joint_names)
from ..joint_limits import DEFAULT_LIMIT_GAIN
from ..linalg import DampingPolicy
from ..step_message import StepMessage
from .analytical import ChainSplit, chain_split
from .extension_sources import stale_extension_reason
from .python_step import PythonStep
from .report import StepReport, report_message, solve_info
from .step_setup import ConstraintPlan, Form, StepSetup
from .tolerances import StepTolerances

if TYPE_CHECKING:
    from .compiled import CompiledStep

Backend = Literal["auto", "compiled", "python"]

#: The environment variable that makes ``backend="auto"`` choose the Python step, as on a
#: machine where the extension is not built (docs/design.md section 16): ``python``; unset,
#: empty or ``auto`` leaves the choice to the build.
BACKEND_VARIABLE = "CJM_BACKEND"


def python_step_forced() -> bool:
    """Whether :data:`BACKEND_VARIABLE` asks ``backend="auto"`` for the Python step
    (``ValueError`` naming the variable for a value other than ``auto`` or ``python``)."""
    value = os.environ.get(BACKEND_VARIABLE, "").strip().lower()
    if value not in ("", "auto", "python"):
        raise ValueError(f"{BACKEND_VARIABLE} must be 'auto' or 'python' (or unset), "
                         f"got {os.environ[BACKEND_VARIABLE]!r}")
    return value == "python"


@cache
def compiled_step_problem() -> str | None:
    """Why the C++ extension of the compiled step (section 16) cannot run here, or None:
    not built, or built from other sources than those beside the package (stale: warned
    once, as ``backend="auto"`` then runs the Python step)."""
    try:
        from ._step import JOINT_KINDS, SHAPE_KINDS, Pipeline, Tick, Tolerances  # noqa: F401  (an older build lacks them)
        from ._step import SOURCES_DIGEST
    except ImportError as error:
        return (f"the compiled CJM step (controllers.cjm._step) is not built or is too old "
                f"({error}): reinstall with pip install -e . (it needs a C++17 compiler)")
    stale = stale_extension_reason(SOURCES_DIGEST)
    if stale is not None:
        warnings.warn(f"{stale}; until then the CJM runs its Python step", RuntimeWarning,
                      stacklevel=2)
    return stale


def compiled_step_available() -> bool:
    """Whether the C++ extension of the compiled step (section 16) can run here."""
    return compiled_step_problem() is None


def read_only(array: np.ndarray) -> np.ndarray:
    """A read-only copy of ``array``: a property's value that is changed by assigning a
    new one, never in place (a change in place would not reach the built step)."""
    copy = np.array(array, dtype=float)
    copy.flags.writeable = False
    return copy


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
    limit_gain, position_limits, velocity_limits, strict, acceleration_limit : see
        :class:`controllers.base.Controller`.
    collisions : the collision pairs kept apart
        (:class:`constraints.collision.CollisionAvoidance`), or None. Their velocity-damper
        rows ``rows qd >= lower`` join the active set after the barriers, below the
        equality rows (docs/design.md section 18.4); :meth:`set_collisions` changes them.
    backend : ``"compiled"`` (the whole step in C++, Pinocchio's kinematics included,
        :mod:`controllers.cjm.compiled`, docs/design.md section 16), ``"python"``
        (:mod:`controllers.cjm.python_step` and the forms: the readable reference) or
        ``"auto"`` (compiled when the extension is built and covers the robot's joints,
        else Python; ``CJM_BACKEND=python``
        in the environment makes it Python, :data:`BACKEND_VARIABLE`). ``"compiled"``
        raises ``ImportError`` without the extension and ``ValueError`` for a robot it
        does not cover. The compiled step computes its kinematics on its own copy of the
        model: it leaves ``self.data`` as it was, except with ``collisions`` on a body it
        does not measure (a mesh's hull), whose rows Python measures on ``self.data``.

    The step itself lives in :attr:`step` (built with :attr:`setup`, again whenever
    ``policy``, ``posture``, ``posture_gain``, ``twist_weight``, the constraints or the
    collisions are set): ``step.solve(q, twist)`` gives ``qd`` and a
    :class:`~controllers.cjm.report.StepReport`, which :meth:`solve` words into ``info``.
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
        acceleration_limit=None,
        collisions: CollisionAvoidance | None = None,
        jerk_limit=None,
    ) -> None:
        super().__init__(robot, dt=dt, limit_gain=limit_gain, position_limits=position_limits,
                         velocity_limits=velocity_limits, strict=strict,
                         acceleration_limit=acceleration_limit, collisions=collisions,
                         jerk_limit=jerk_limit)
        if parametrisation not in ("nullspace", "paper"):
            raise ValueError(f"unknown parametrisation {parametrisation!r}: 'nullspace' or 'paper'")
        if form not in ("auto", "general"):
            raise ValueError(f"unknown form {form!r}: 'auto' or 'general'")
        if backend not in ("auto", "compiled", "python"):
            raise ValueError(f"unknown backend {backend!r}: 'auto', 'compiled' or 'python'")
        available = compiled_step_available()
        if backend == "compiled" and not available:
            raise ImportError(compiled_step_problem())
        unsupported = unsupported_joint_kinds(self.model) if available else []
        if backend == "compiled" and unsupported:
            raise ValueError(f"the compiled CJM step does not cover joints of kind "
                             f"{', '.join(unsupported)}: use backend='python'")
        #: whether the Python step may stand in when the compiled one cannot take the robot
        self._python_if_needed = backend == "auto"
        if backend == "auto":
            compiled = available and not unsupported and not python_step_forced()
            backend = "compiled" if compiled else "python"
        self.backend: Backend = backend
        self.parametrisation: Parametrisation = parametrisation
        self.form: Form = form
        self._policy = DampingPolicy(as_number(damping, "damping", 0.0),
                                     as_number(singular_threshold, "singular_threshold", 0.0),
                                     as_number(max_damping, "max_damping", 0.0))
        self._posture_gain = as_number(posture_gain, "posture_gain", 0.0)
        self._twist_weight = read_only(as_twist_weight(twist_weight, self.task_size))
        if posture is None:
            posture = getattr(robot, "q_home", None)
        self._posture = read_only(pin.neutral(self.model) if posture is None
                                  else as_vector(posture, self.model.nq, "posture"))
        self._splits: dict[int, ChainSplit | None] = {}
        #: the last step's :class:`StepReport` (:attr:`report`), None until read
        self._report: StepReport | None = StepReport()
        #: whether a step ran since ``self.data`` last had kinematics (the compiled step
        #: computes its own and leaves ``self.data`` as it was)
        self._data_behind = False
        #: joint name per velocity index (a multi-dof joint repeats its name)
        self.joint_names = velocity_joint_names(self.model)
        self.set_constraints(constraints)

    # -- what the step is built from: setting any of it builds the step again ----------

    @property
    def policy(self) -> DampingPolicy:
        """The DLS damping (eq 35; :class:`controllers.linalg.DampingPolicy`)."""
        return self._policy

    @policy.setter
    def policy(self, policy: DampingPolicy) -> None:
        if not isinstance(policy, DampingPolicy):
            raise ValueError(f"policy must be a DampingPolicy, got {policy!r}")
        self._change(_policy=policy)

    @property
    def posture(self) -> np.ndarray:
        """Configuration the redundancy is spent on (nq,; read-only: assign a new one)."""
        return self._posture

    @posture.setter
    def posture(self, posture: np.ndarray) -> None:
        self._change(_posture=read_only(as_vector(posture, self.model.nq, "posture")))

    @property
    def posture_gain(self) -> float:
        """Gain (1/s) of the null-space posture task; 0 gives minimum norm."""
        return self._posture_gain

    @posture_gain.setter
    def posture_gain(self, gain: float) -> None:
        self._change(_posture_gain=as_number(gain, "posture_gain", 0.0))

    @property
    def twist_weight(self) -> np.ndarray:
        """Diagonal weight ``W`` of the twist error (task_size,; read-only: assign a new one)."""
        return self._twist_weight

    @twist_weight.setter
    def twist_weight(self, twist_weight) -> None:
        self._change(_twist_weight=read_only(as_twist_weight(twist_weight, self.task_size)))

    def _change(self, **values) -> None:
        """Set the attributes ``values`` and build the step again; a build that is refused
        restores them, so the controller keeps the step it had and says what it holds."""
        previous = {name: getattr(self, name) for name in values}
        for name, value in values.items():
            setattr(self, name, value)
        try:
            self._prepare()
        except Exception:
            for name, value in previous.items():
                setattr(self, name, value)
            raise

    def _prepare(self) -> None:
        """Build the step setup and the backend's step from it (after any change)."""
        if self.parametrisation == "paper":
            for constraint in self.constraints:
                if not constraint.has_paper_form:
                    raise ValueError(
                        f"parametrisation='paper' does not cover {type(constraint).__name__} "
                        "(its 1/a form needs the constrained directions perpendicular to p "
                        "at every configuration, as a hole's are): use 'nullspace'")
        setup = self._step_setup()
        step: PythonStep | CompiledStep = PythonStep(setup, self.data)
        if self.backend == "compiled":
            from .compiled import CompiledStep, KinematicsMismatch

            try:
                step = CompiledStep(setup, self.data)
            except KinematicsMismatch:
                if not self._python_if_needed:
                    raise
                self.backend = "python"
        if getattr(self, "step", None) is not None:
            self._report = self.report
        # a rebuilt step goes on from the command last sent
        step.previous[:] = self.command_box.previous_command
        step.previous_change[:] = self.command_box.previous_change
        #: everything the step needs (:class:`controllers.cjm.step_setup.StepSetup`)
        self.setup = setup
        self.step = step

    def _step_setup(self) -> StepSetup:
        """The :class:`StepSetup` of the controller's current options and constraints."""
        weight = self._twist_weight
        # the task entries asked for (weight > 0: a zero-weight row would read as a
        # singular direction and bring the damping in), or None for the identity
        task_entries = None if np.all(weight == 1.0) else np.flatnonzero(weight > 0.0)
        task_scale = np.sqrt(weight if task_entries is None else weight[task_entries])
        paper_task = self.task_size == 6 and task_entries is None
        plans = []
        for constraint, frame in zip(self.constraints, self.constraint_frames):
            split = self.split(frame)
            analytical = paper_task and split is not None and split.pre.size >= 6
            plans.append(ConstraintPlan(constraint, frame, split, analytical))
        return StepSetup(
            model=self.model, ee_frame_ids=tuple(self.ee_frame_ids), plans=tuple(plans),
            bounds=self.joint_bounds, box_test=self._box_test, policy=self._policy,
            tolerances=StepTolerances(), task_entries=task_entries, task_scale=task_scale,
            posture=self._posture.copy(), posture_gain=self._posture_gain,
            posture_free=self._base_velocity,
            parametrisation=self.parametrisation, form=self.form, joint_names=self.joint_names,
            collisions=self.collisions)

    # -- the step ----------------------------------------------------------------------

    @property
    def step(self) -> PythonStep | CompiledStep:
        """The backend's step (PythonStep or CompiledStep): ``step.run(q, twist) -> qd``.
        It keeps the commands sent; :attr:`command_box` reads them from it, wherever it
        keeps them (a compiled step that grows for more collision rows moves them)."""
        return self._step

    @step.setter
    def step(self, step: PythonStep | CompiledStep) -> None:
        self._step = step
        self.command_box.history = step

    def solve(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """:meth:`Controller.solve`, by the backend's step (docs/design.md section 16):
        its report, built when :attr:`report` is read, worded into :attr:`info`."""
        qd = self.step.run(q, twist)
        self._took_report(None)
        return qd

    def take_report(self, report: StepReport) -> None:
        """A step's report kept in :attr:`report`, worded into :attr:`info` when that is
        read (``SolverError`` for a failed step when ``strict``)."""
        self._took_report(report)

    def _took_report(self, report: StepReport | None) -> None:
        """A step ran: ``report`` (None: the step's :meth:`run_report`, built when read)."""
        self._report = report
        self._info: SolveInfo | None = None
        self._data_behind = True
        if self.strict and self.report.status is StepStatus.FAILED:
            raise SolverError(self.info.message)

    @property
    def report(self) -> StepReport:
        """The last step's :class:`~controllers.cjm.report.StepReport`, built from the
        backend's on the first read after the step (a step nobody asks about costs no
        report: docs/design.md 16)."""
        report = self._report
        if report is None:
            report = self._report = self.step.run_report()
        return report

    @property
    def info(self) -> SolveInfo:
        """How the last step went: :attr:`report` worded on the first read after the step
        (:func:`~controllers.cjm.report.solve_info`; docs/design.md 16), so that a step
        nobody asks about costs no words."""
        info = self._info
        if info is None:
            info = self._info = solve_info(self.report, self.joint_names)
        return info

    @info.setter
    def info(self, info: SolveInfo) -> None:
        self._info = info

    def step_outcome(self) -> tuple[StepStatus, StepMessage]:
        """:meth:`Controller.step_outcome` from :attr:`report`: its status, and its
        message worded on the first read of its text
        (:func:`~controllers.cjm.report.report_message`, the words of ``info.message``),
        so that a period whose message nobody reads costs no words (docs/design.md 16).
        ``info``'s own once it was read or set."""
        if self._info is not None:
            return super().step_outcome()
        return self.report.status, StepMessage(partial(report_message, self.report,
                                                       self.joint_names))

    def loop_tick(self, dt: float, kp: float, max_linear_speed: float, max_angular_speed: float,
                  target_time_constant: float, feed_forward: bool):
        """The closed loop's hot path in C++ around the compiled step
        (:class:`~controllers.cjm.compiled_tick.CompiledTick`, docs/design.md 5.1), or
        None on the Python backend."""
        if self.backend != "compiled":
            return None
        from .compiled_tick import CompiledTick

        return CompiledTick(self, dt, kp, max_linear_speed, max_angular_speed,
                            target_time_constant, feed_forward)

    def _kinematics(self, q: np.ndarray) -> Kinematics:
        self._data_behind = False
        return super()._kinematics(q)

    def constraint_rows(
        self, indices: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`Controller.constraint_rows` at the configuration of the last step (the
        compiled step computes its kinematics on its own copy of the model, and ``self.data``
        is brought to that configuration first), or at the kinematics last computed here."""
        if self._data_behind:
            solved = self.step.solved_configuration()
            if solved is not None:
                self._kinematics(solved)
            self._data_behind = False
        return super().constraint_rows(indices)

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
