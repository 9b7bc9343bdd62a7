"""What every controller shares: input checks, kinematics, joint limits and the step report."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from enum import Enum
from typing import Any, Iterable, Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint, RobotLike
from constraints.collision import CollisionAvoidance, CollisionRows
from constraints.kinematics import resolve_frame
from constraints.validation import as_vector

from .command_box import CommandBox
from .joint_limits import DEFAULT_LIMIT_GAIN, BoxTest, JointBounds
from .linalg import DampingPolicy
from .step_message import StepMessage

#: An equality row is held when ``|A qd - b|`` is at most this (m/s); above it the step
#: reports ``constraint_degraded``.
EQUALITY_TOLERANCE = 1e-9


#: ``J_e qd`` meets the twist when ``max |J_e qd - V_e|`` is at most this times
#: ``1 + max |V_e|`` (the QP's Tikhonov term alone leaves about 1e-9 relative).
TWIST_TOLERANCE = 1e-6


def residual_note(residual: float) -> str:
    return f"constraint residual {residual:.2e} m/s"


def with_note(message: str, note: str) -> str:
    """``message`` with ``note`` added after a ``"; "`` (not again when it holds it)."""
    if not note or note in message:
        return message
    return f"{message}; {note}" if message else note


def clipped_note(joints: list[int], change: float) -> str:
    return (f"clipped to the joint limits (joints {joints}, by up to {change:.2e} rad/s): "
            "constraints not held exactly")


#: numpy's float64 dtype (one object: the inputs' fast path tests it by identity; a
#: float64 of the other byte order takes the slow path, which converts it)
FLOAT64 = np.dtype(np.float64)

#: The message of a step whose command came out non-finite (the command is the stop:
#: the command nearest zero inside the box).
NON_FINITE_NOTE = "non-finite joint velocity computed"


def checked_inputs(q: np.ndarray, twist: np.ndarray, nq: int,
                   task_size: int) -> tuple[np.ndarray, np.ndarray]:
    """``q`` (nq,) and ``twist`` (task_size,) as finite real float arrays, else
    ``ValueError`` naming the field (a complex twist is refused, not cast: its imaginary
    part would be dropped)."""
    q = np.asarray(q)
    twist = np.asarray(twist)
    # one cheap test for the common case (float64 arrays of the right sizes, finite);
    # as_vector converts integers and says what is wrong otherwise
    if (q.dtype is not FLOAT64 or twist.dtype is not FLOAT64
            or q.shape != (nq,) or twist.shape != (task_size,)
            or not math.isfinite(sum(q.tolist()) + sum(twist.tolist()))):
        q = as_vector(q, nq, "q")
        twist = as_vector(twist, task_size, "twist")
    return q, twist


class SolverError(RuntimeError):
    """A controller could not compute a command (raised only with ``strict=True``)."""


class StepStatus(str, Enum):
    """What a command is, from best to worst (docs/design.md section 8).

    * ``ok``: every constraint row held and the EE twist met as asked (up to the DLS
      damping of a well-conditioned problem, which is zero).
    * ``scaled``: the task slowed down by a factor < 1 so every joint stays in its limits.
    * ``least_squares``: the task is not fully achievable (fewer free DoF than the task,
      a singularity, damping acting): the closest twist is commanded.
    * ``constraint_degraded``: a constraint is not held exactly (conflicting constraints,
      or the joint limits cannot accommodate its correction).
    * ``failed``: no command could be computed; the command is the stop, the command
      nearest zero inside the box (zero unless a joint past its limit must come back).
    """

    OK = "ok"
    SCALED = "scaled"
    LEAST_SQUARES = "least_squares"
    CONSTRAINT_DEGRADED = "constraint_degraded"
    FAILED = "failed"

    @property
    def severity(self) -> int:
        return _SEVERITY[self]


_SEVERITY = {status: rank for rank, status in enumerate(StepStatus)}


@dataclass
class SolveInfo:
    """How the last ``solve`` went. Read it after every call: ``controller.info``.

    Attributes
    ----------
    status : what the command is (:class:`StepStatus`).
    method : ``"analytical"``, ``"general"``, ``"saturated"`` (CJM), ``"qp:<solver>"``
        or ``"mink:<solver>"``.
    message : why the status is not ``ok``, in words; empty when all went as planned.
    sigma_min : smallest singular value of the constrained Jacobian ``Jbar`` (CJM). On
        the analytical LU fast path this is the bound ``1 / ||Jbar^-1||_F``, between
        ``sigma_min / sqrt(6)`` and ``sigma_min``: it never overstates the distance to
        a singularity.
    damping : the DLS damping ``lambda`` used (CJM).
    scale : the factor (<= 1) applied to the task to respect the joint limits.
    saturated_joints : velocity indices of the joints held at a limit (CJM).
    active_barriers : indices (into ``constraints``) of the barriers held as equalities.
    equality_residual : ``max |A qd - b|`` over the equality rows held (m/s).
    minimum_distance : with collision avoidance, the smallest distance (m) between the
        pairs it measured at this step (``inf`` when none was within the detection
        distance, or without collision avoidance); ``closest_pair`` names that pair.
    active_pairs : the collision pairs whose rows the command holds at their bound
        (docs/design.md section 18).
    """

    status: StepStatus = StepStatus.OK
    method: str = ""
    message: str = ""
    sigma_min: float = float("nan")
    damping: float = 0.0
    scale: float = 1.0
    saturated_joints: tuple[int, ...] = ()
    active_barriers: tuple[int, ...] = ()
    equality_residual: float = 0.0
    minimum_distance: float = float("inf")
    closest_pair: str = ""
    active_pairs: tuple[str, ...] = ()

    @property
    def success(self) -> bool:
        """False only for the zero-velocity fallback (``status == "failed"``)."""
        return self.status is not StepStatus.FAILED

    def report(self, status: StepStatus, note: str = "") -> None:
        """Lower the status to ``status`` if it is worse, and add ``note`` to the message."""
        if status.severity > self.status.severity:
            self.status = status
        self.message = with_note(self.message, note)


def report_twist_error(info: SolveInfo, jacobian: np.ndarray, qd: np.ndarray,
                       twist: np.ndarray, weight_root: np.ndarray | None = None) -> bool:
    """``least_squares`` in ``info`` when ``J_e qd`` misses the twist (optimisers trade it
    off), each entry's miss scaled by ``W^1/2`` (``weight_root``) when the task is weighted;
    returns whether it missed."""
    miss = jacobian @ qd - twist
    if weight_root is not None:
        miss *= weight_root
    error = float(np.max(np.abs(miss)))
    if error > TWIST_TOLERANCE * (1.0 + float(np.max(np.abs(twist)))):
        info.report(StepStatus.LEAST_SQUARES,
                    f"twist not met exactly (error {error:.2e}): limits, barriers, "
                    "constraints or a singularity")
        return True
    return False


class Kinematics:
    """Kinematic quantities at one configuration, computed once per step.

    Attributes
    ----------
    q : the configuration.
    ee_jacobian : (6 n, nv) ``LOCAL`` Jacobians of the robot's n EE frames, stacked in
        ``robot.ee_frames`` order (the task Jacobian ``J_e``).
    ee_placement : world placement of the first EE frame (read from ``data`` on first
        use, so the controllers that do not need it do not pay for an ``SE3`` object).
    """

    __slots__ = ("q", "ee_jacobian", "_data", "_ee_frame_id", "_ee_placement")

    def __init__(self, q: np.ndarray, ee_jacobian: np.ndarray, data: pin.Data,
                 ee_frame_id: int) -> None:
        self.q = q
        self.ee_jacobian = ee_jacobian
        self._data = data
        self._ee_frame_id = ee_frame_id
        self._ee_placement: pin.SE3 | None = None

    @property
    def ee_placement(self) -> pin.SE3:
        if self._ee_placement is None:
            self._ee_placement = self._data.oMf[self._ee_frame_id]
        return self._ee_placement


def velocity_joint_names(model: pin.Model) -> tuple[str, ...]:
    """The joint name of each velocity index (a joint of several repeats its name)."""
    return tuple(model.names[joint_id] for joint_id in range(1, model.njoints)
                 for _ in range(model.nvs[joint_id]))


def posture_difference(model: pin.Model, q: np.ndarray, posture: np.ndarray,
                       free: slice | None) -> np.ndarray:
    """``posture (-) q`` (nv,, ``pin.difference``) with the entries ``free`` (a mobile
    base's) zero: the posture shapes the joints; the base stands where it is unless the
    task or a constraint moves it (docs/design.md section 11.3)."""
    difference = pin.difference(model, q, posture)
    if free is not None:
        difference[free] = 0.0
    return difference


def as_constraint_list(constraints: Iterable[Constraint]) -> list[Constraint]:
    """``constraints`` as a list of ``Constraint`` objects, else ``ValueError``."""
    if constraints is None or isinstance(constraints, (str, bytes, Constraint)):
        raise ValueError(f"constraints must be a list of Constraint objects, got {constraints!r}")
    try:
        constraints = list(constraints)
    except TypeError:
        raise ValueError(
            f"constraints must be a list of Constraint objects, got {constraints!r}") from None
    for constraint in constraints:
        if not isinstance(constraint, Constraint):
            raise ValueError(f"constraints must hold Constraint objects, got {constraint!r}")
    return constraints


def as_twist_weight(twist_weight, task_size: int) -> np.ndarray:
    """The diagonal weight ``W`` (task_size,) of the twist error: identity for None; 6
    values apply to every EE, ``task_size`` values to each entry. ``ValueError`` for
    negative or non-finite weights, all zeros (no task: each controller's task stage
    needs a row; docs/design.md section 20), or another size."""
    if twist_weight is None:
        return np.ones(task_size)
    size = 6 if np.shape(twist_weight) == (6,) else task_size
    weight = np.tile(as_vector(twist_weight, size, "twist_weight"), task_size // size)
    if np.any(weight < 0):
        raise ValueError(f"twist_weight must be non-negative, got {weight.tolist()}")
    if not np.any(weight > 0):
        raise ValueError("twist_weight must be positive on some entry: all zeros asks the "
                         "end effectors for nothing")
    return weight


class Controller(ABC):
    """Turns a desired end-effector body twist into joint velocities under constraints.

    Every command is finite and inside the joint box of :class:`JointBounds` (velocity
    limits, and position limits through ``dt``): a solution that leaves the box is
    corrected (the CJM: saturation in the null space, section 9; the others, through
    :class:`GuardedController`: clipping, reported as ``constraint_degraded``).

    Subclasses set their own attributes first and call :meth:`set_constraints` last in
    their ``__init__``; :meth:`_prepare` then sees a fully built object.

    Parameters
    ----------
    robot : a ``teleop.Robot`` (anything with ``model``, ``ee_frame``, ``q_home``; several
        end effectors when it has ``ee_frames``: the twist then stacks 6 entries per frame).
    dt : control period (s): how far a joint may go towards a position limit per step.
    limit_gain : fraction of the distance to a position limit allowed per step.
    position_limits, velocity_limits : enforce these limits (False: a bare solver, for
        cross-checks only; never on a robot).
    strict : raise ``SolverError`` instead of returning the fallback (a controlled stop).
    acceleration_limit : (nv,) per joint (rad/s^2, m/s^2 for prismatic and base
        translations; ``inf`` for none), or None for no acceleration limit. The reference
        is the previous command (:attr:`command_box`, zero after :meth:`reset`); the box of a
        step is then the intersection of the velocity, braking-aware position and
        acceleration bounds (docs/design.md section 8.4).
    jerk_limit : (nv,) per joint (rad/s^3, m/s^3; ``inf`` for none), or None: the
        command's change may differ from the previous change by at most ``j dt^2``
        (docs/design.md section 8.5); needs ``acceleration_limit``. Where the other limits
        leave no room within it (braking at a position limit), it gives way to them.
    """

    #: the damped least squares' policy (paper eq 35) of a controller that damps its task
    #: near singularities (all three here), else None; assign a new one to change it
    policy: DampingPolicy | None = None

    def __init__(self, robot: RobotLike, dt: float = 1e-3,
                 limit_gain: float = DEFAULT_LIMIT_GAIN, position_limits: bool = True,
                 velocity_limits: bool = True, strict: bool = False,
                 acceleration_limit=None, collisions: CollisionAvoidance | None = None,
                 jerk_limit=None) -> None:
        self.robot = robot
        self.model: pin.Model = robot.model
        self.data: pin.Data = self.model.createData()
        named: Any = robot  # a robot names its end effectors: ee_frames, or one ee_frame
        self.ee_frame_ids = [resolve_frame(self.model, name)
                             for name in getattr(named, "ee_frames", None) or (named.ee_frame,)]
        self.ee_frame_id = self.ee_frame_ids[0]
        #: entries of the stacked EE twist: 6 per end effector
        self.task_size = 6 * len(self.ee_frame_ids)
        self.strict = bool(strict)
        self.info = SolveInfo()
        self.joint_bounds = JointBounds(self.model, dt, limit_gain, position_limits,
                                        velocity_limits, acceleration_limit, jerk_limit)
        #: the box of each step and the commands it counts from
        self.command_box = CommandBox(self.joint_bounds, self.model.nv)
        self.velocity_limit = self.joint_bounds.velocity_limit
        self._box_test = BoxTest(self.joint_bounds, self.model.nq, self.model.nv)
        self.constraints: list[Constraint] = []
        self.constraint_frames: list[int] = []
        #: the collision pairs kept apart (docs/design.md section 18), or None
        self.collisions: CollisionAvoidance | None = None
        if collisions is not None:
            collisions.check(self.model, self.dt)
            self.collisions = collisions
            collisions.set_ports(self.constraints)
        #: a mobile base's velocity indices: no posture there (docs/design.md section 11.3)
        self._base_velocity = (slice(0, self.model.nvs[1])
                               if getattr(robot, "root_joint", "fixed") == "planar" else None)

    @property
    def dt(self) -> float:
        """Control period (s)."""
        return self.joint_bounds.dt

    def bounds(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The joint box ``lower <= qd <= upper`` of the next step at ``q``
        (:meth:`CommandBox.box`)."""
        return self.command_box.box(q)

    def reset(self) -> None:
        """Forget the commands sent: the next step starts from rest."""
        self.command_box.reset()

    def stop(self, q: np.ndarray) -> np.ndarray:
        """:meth:`CommandBox.stop_command` sent in place of a step (the loop's answer to an
        input the controller refused): it becomes the previous command the next step's
        acceleration box counts from."""
        command = self.command_box.stop_command(q)
        self.command_box.remember(command)
        return command

    def loop_tick(self, dt: float, kp: float, max_linear_speed: float, max_angular_speed: float,
                  target_time_constant: float, feed_forward: bool) -> object | None:
        """The closed loop's hot path compiled around this controller's step, when it has
        one (the CJM's compiled backend: docs/design.md 5.1); None: the loop runs its
        Python reference."""
        return None

    # -- constraints -------------------------------------------------------------------

    def set_constraints(self, constraints: Iterable[Constraint]) -> None:
        """Replace the constraint set; unknown links, gains unstable at ``dt`` and sets the
        controller cannot take raise ``ValueError`` here, leaving the set it had. A
        constraint's gain may change afterwards (its setter checks it): every controller
        reads it at each step."""
        constraints = as_constraint_list(constraints)
        for constraint in constraints:
            constraint.check_gain(self.dt)
        frames = [resolve_frame(self.model, c.link) for c in constraints]
        previous = self.constraints, self.constraint_frames
        self.constraints, self.constraint_frames = constraints, frames
        try:
            self._prepare()
        except Exception:  # refused: the controller keeps, and says, the set it holds
            self.constraints, self.constraint_frames = previous
            raise
        if self.collisions is not None:
            self.collisions.set_ports(constraints)

    def set_collisions(self, collisions: CollisionAvoidance | None) -> None:
        """Keep the pairs of ``collisions`` apart from the next step on, or none (None).

        ``collisions`` must be built on this controller's robot model, with a damper
        stable at ``dt`` (else ``ValueError``, and the controller keeps what it had).
        """
        if collisions is not None:
            collisions.check(self.model, self.dt)
        previous = self.collisions
        self.collisions = collisions
        try:
            self._prepare()
        except Exception:
            self.collisions = previous
            raise
        if collisions is not None:
            collisions.set_ports(self.constraints)

    def collision_rows(self) -> CollisionRows | None:
        """The avoidance rows at the kinematics in ``self.data`` (joint placements and
        Jacobians computed), or None without collision avoidance."""
        if self.collisions is None:
            return None
        return self.collisions.rows(self.model, self.data)

    def _prepare(self) -> None:
        """Precompute per-constraint data after :meth:`set_constraints` (override)."""

    # -- the step ----------------------------------------------------------------------

    @abstractmethod
    def solve(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """Joint velocities (nv,) for the desired EE body twist ``[v; w]`` (``LOCAL``),
        6 entries per end effector in ``robot.ee_frames`` order (docs/design.md section 11).

        Bad input (wrong size, NaN or inf) raises ``ValueError``. A numerical failure
        returns :meth:`CommandBox.stop_command` (zeros without acceleration limits) with
        ``self.info.status == "failed"`` (or raises ``SolverError``
        when the controller is ``strict``): never a non-finite command, never one
        outside the joint box.
        """

    def step_outcome(self) -> tuple[StepStatus, StepMessage]:
        """The last step's status and its message, the message's text worded when read
        (:class:`~controllers.step_message.StepMessage`): ``info.status`` and
        ``info.message``, the same words (docs/design.md section 8.3)."""
        info = self.info
        return info.status, StepMessage.worded(info.message)

    def _fail(self, message: str, q: np.ndarray) -> np.ndarray:
        self.info.status = StepStatus.FAILED
        self.info.message = message
        if self.strict:
            raise SolverError(message)
        return self.command_box.stop_command(q)

    def _kinematics(self, q: np.ndarray) -> Kinematics:
        """Joint Jacobians and frame placements at ``q`` in ``self.data``, and the EE
        frames' ``LOCAL`` Jacobians, stacked (6 n, nv)."""
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        if len(self.ee_frame_ids) == 1:
            ee_jacobian = pin.getFrameJacobian(model, data, self.ee_frame_id, pin.LOCAL)
        else:
            ee_jacobian = np.vstack([pin.getFrameJacobian(model, data, frame, pin.LOCAL)
                                     for frame in self.ee_frame_ids])
        return Kinematics(q, ee_jacobian, data, self.ee_frame_id)

    # -- shared pieces -----------------------------------------------------------------

    def constraint_rows(
        self, indices: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Stacked rows ``(A, b)`` of the chosen constraints at the current kinematics."""
        if indices is None:
            indices = range(len(self.constraints))
        blocks = [self.constraints[i].rows(self.model, self.data, self.constraint_frames[i])
                  for i in indices]
        if len(blocks) == 1:
            return blocks[0]
        if not blocks:
            return np.zeros((0, self.model.nv)), np.zeros(0)
        return np.vstack([A for A, _ in blocks]), np.concatenate([b for _, b in blocks])

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(robot={getattr(self.robot, 'name', '?')!r}, "
                f"constraints={self.constraints!r})")


class GuardedController(Controller):
    """A controller whose step is one template: its own :meth:`_solve` at the current
    kinematics, then the guards every command passes (the QP baseline and mink; the CJM
    runs the same guards inside its step backends, docs/design.md section 16)."""

    def solve(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """:meth:`Controller.solve`: the kinematics at ``q``, :meth:`_solve`, then the
        guards (a non-finite command fails; one outside the box goes through
        :meth:`_clip`; an equality residual above ``EQUALITY_TOLERANCE`` degrades the
        step)."""
        q, twist = checked_inputs(q, twist, self.model.nq, self.task_size)
        self.info = SolveInfo()
        kinematics = self._kinematics(q)
        try:
            qd = self._solve(kinematics, twist)
        except (np.linalg.LinAlgError, SolverError) as error:
            qd = self._fail(f"{type(error).__name__}: {error}", q)
        else:
            if not math.isfinite(sum(qd.tolist())):  # any NaN/inf (or overflow) poisons the sum
                qd = self._fail(NON_FINITE_NOTE, q)
            else:
                qd = self._clip(q, qd)
        self.command_box.remember(qd)
        return qd

    def _clip(self, q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        """The last guard: ``qd`` clipped to the box at ``q`` (a change beyond rounding
        degrades the step, as does an equality residual above ``EQUALITY_TOLERANCE``)."""
        box = self.command_box
        previous = box.previous_command if self.joint_bounds.acceleration_step is not None else None
        change = box.jerk_reference
        if not self._box_test.contains(q, qd, previous, change):
            lower, upper = self.joint_bounds.box(q, previous, change)
            clipped = np.clip(qd, lower, upper)
            if not math.isfinite(sum(clipped.tolist())):  # clipping passes a NaN through
                return self._fail(NON_FINITE_NOTE, q)
            moved = float(np.max(np.abs(clipped - qd), initial=0.0))
            if moved > EQUALITY_TOLERANCE * (1.0 + float(np.max(np.abs(qd), initial=0.0))):
                joints = np.flatnonzero(clipped != qd).tolist()
                self.info.report(StepStatus.CONSTRAINT_DEGRADED, clipped_note(joints, moved))
                self.info.saturated_joints = tuple(joints)
                A, b = self.constraint_rows([i for i, c in enumerate(self.constraints)
                                             if c.is_equality])
                if A.shape[0]:
                    self.info.equality_residual = float(np.max(np.abs(A @ clipped - b)))
            qd = clipped
        if self.info.equality_residual > EQUALITY_TOLERANCE:
            self.info.report(StepStatus.CONSTRAINT_DEGRADED,
                             residual_note(self.info.equality_residual))
        return qd

    @abstractmethod
    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        """Compute ``qd``; the kinematics in ``self.data`` are up to date."""
