"""The browser session's core, without any browser: state, actions, the control thread.

Everything the UI does goes through :class:`TeleopApp`, so it can be tested without
viser. All public methods are thread-safe (one lock); actions that cannot be done raise
``ValueError`` with a message meant for the operator (the UI shows it as a notification).

Threading (docs/design.md section 5.3): :class:`ControlThread` calls :meth:`TeleopApp.step`
at the control rate and never touches viser; the view thread reads
:meth:`TeleopApp.snapshot`.

The operator's input device is the target gizmo (:meth:`TeleopApp.move_gizmo`). As on a
surgical or industrial console, a **clutch** (:meth:`TeleopApp.set_clutch`) decouples it
from the target, and **motion scaling** (:meth:`TeleopApp.set_motion_scale`) maps a gizmo
displacement ``d`` since the last clutch release to a target displacement ``scale d``
(orientation follows the gizmo's rotation since then, unscaled).

A robot with several end effectors (``robot.ee_frames``, docs/design.md section 11) has a
target and a gizmo per EE (:class:`EEInput`); the actions on them take the EE's index
``ee`` (0: ``robot.ee_frame``). The clutch and the motion scale are the console's, shared
by every gizmo; each gizmo keeps its own anchors.
"""

from __future__ import annotations

import collections
import dataclasses
import itertools
import math
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np
import pinocchio as pin

from constraints import Barrier, Constraint, Hole, Plane, PointLock
from constraints.kinematics import frame_placement
from constraints.validation import as_number, as_vector
from controllers import StepStatus
from teleop.controller_specs import make_controller
from teleop.experiments.sessions import SessionRecorder
from teleop.loop import LoopConfig, StepRecord, TeleopLoop
from teleop.loop.moving_geometry import advance, steer
from teleop.robots import Robot

from .folders import Folder
from .scene import FORMAT as SCENE_FORMAT
from .scene import VERSION as SCENE_VERSION
from .scene import (
    parse_scene,
    read_scene_file,
    robot_source,
    robot_to_dict,
    same_robot,
    write_scene_file,
)

#: the operator's target and moved geometry are smoothed with this time constant (s)
DEFAULT_SMOOTHING = 0.05
#: EE speed caps of the operator's command. A dragged gizmo jumps by centimetres; at these
#: speeds the sda10f (about 40 rad/s of joint speed per m/s at its EE with a hole on link 6)
#: stays within its joint-velocity limits and the hole's discretisation error below 1 um.
MAX_LINEAR_SPEED = 0.05  # m/s
MAX_ANGULAR_SPEED = 0.5  # rad/s
#: seconds of history kept for the live plots
HISTORY_SECONDS = 10.0
#: history samples per second: the measures (constraint errors, EE error, ...) are taken
#: on these ticks only; every other tick computes just what the controller needs
HISTORY_RATE = 50.0
#: the motion scale is a number in (0, MAX_MOTION_SCALE]
MAX_MOTION_SCALE = 10.0
#: a plane's point on a link without an instrument axis is at most this far from its origin (m)
MAX_LINK_POINT = 2.0
#: the ghost's offset from the main robot is at most this long (m)
MAX_GHOST_OFFSET = 5.0
#: an EE target (or a constraint's goal) is refused farther than this from where the EE
#: (or the constraint) is now (m): no arm reaches farther, and a number such as 1e300
#: would otherwise reach the controllers as a twist of that size
MAX_TARGET_DISTANCE = 2.0
#: the CJM's constant damping lambda is at most this (the slider offers 0-0.2; at 1 the
#: damped inverse barely moves the robot)
MAX_DAMPING = 1.0
#: the control rate (Hz) is between these
MIN_RATE, MAX_RATE = 50.0, 5000.0
#: the EE is "on target" within this distance (m); it does not follow its target when it
#: approaches it at less than FOLLOWING of the commanded speed, or moves at less than
#: STALLED_SPEED (m/s) when the command is that slow
ON_TARGET = 1e-3
FOLLOWING = 0.2
STALLED_SPEED = 1e-3

_HISTORY_LENGTH = int(HISTORY_SECONDS * HISTORY_RATE)
#: the plotted measures of each robot, in the order of the plots
TRACE_COLUMNS = ("constraint_error", "constraint_velocity", "ee_error", "step_time")


@dataclass
class ConstraintEntry:
    """A constraint placed by the operator, with the geometry its gizmo drives."""

    id: str
    constraint: Constraint
    goal: np.ndarray  # where the operator put it (the control loop moves towards it)
    settled: bool = True  # at its goal and at rest: the tick leaves it alone

    @property
    def kind(self) -> str:
        """The constraint's ``kind`` ("hole", "plane", "barrier", "point_lock")."""
        return self.constraint.kind

    @property
    def position(self) -> np.ndarray:
        """Where the geometry is now (world reference point, a copy)."""
        return self.constraint.position


@dataclass
class EEInput:
    """The operator's input for one end effector: its target, its gizmo, and the poses of
    both at the last re-anchoring (clutch release, motion-scale change, nudge)."""

    frame: str  # the EE frame (an entry of robot.ee_frames)
    target: pin.SE3
    gizmo: pin.SE3
    gizmo_anchor: pin.SE3
    target_anchor: pin.SE3

    @classmethod
    def at(cls, frame: str, pose: pin.SE3) -> "EEInput":
        """Target and gizmo both at ``pose``."""
        return cls(frame, pose.copy(), pose.copy(), pose.copy(), pose.copy())

    def reanchor(self) -> None:
        """From now on the target moves by the gizmo's motion since this instant."""
        self.gizmo_anchor = self.gizmo.copy()
        self.target_anchor = self.target.copy()

    def followed(self, scale: float) -> pin.SE3:
        """The target the gizmo asks for: the target anchor moved by ``scale`` times the
        gizmo's displacement since its anchor, turned by the gizmo's rotation since then."""
        anchor, start = self.gizmo_anchor, self.target_anchor
        position = start.translation + scale * (self.gizmo.translation - anchor.translation)
        rotation = self.gizmo.rotation @ anchor.rotation.T @ start.rotation
        return pin.SE3(rotation, position)


def _deque() -> collections.deque:
    return collections.deque(maxlen=_HISTORY_LENGTH)


@dataclass
class Trace:
    """Rolling history of one robot's measures for the live plots (app time ``t``)."""

    t: collections.deque = field(default_factory=_deque)
    constraint_error: collections.deque = field(default_factory=_deque)
    constraint_velocity: collections.deque = field(default_factory=_deque)
    ee_error: collections.deque = field(default_factory=_deque)
    step_time: collections.deque = field(default_factory=_deque)
    #: |qd - qd_main| (rad/s): the ghost's deviation from the main robot's command
    qd_deviation: collections.deque = field(default_factory=_deque)

    def add(self, record: StepRecord, qd_deviation: float = 0.0) -> None:
        self.t.append(record.t)
        self.constraint_error.append(max(record.constraint_error, record.barrier_penetration))
        self.constraint_velocity.append(float(np.linalg.norm(record.constraint_velocity)))
        self.ee_error.append(record.ee_position_error)
        self.step_time.append(record.step_time_us)
        self.qd_deviation.append(qd_deviation)

    def arrays(self) -> dict[str, np.ndarray]:
        return {name: np.array(getattr(self, name), dtype=float)
                for name in ("t", *TRACE_COLUMNS, "qd_deviation")}


@dataclass(frozen=True)
class Limitation:
    """What limits a robot now: the step status (it colours the EE-target line) and why,
    in words."""

    status: str  # a StepStatus value
    words: str
    distance: float  # EE to target (m)


def _pose_to_dict(pose: pin.SE3) -> dict:
    """``{"position": [x, y, z], "wxyz": [w, x, y, z]}`` (a scene's target)."""
    quaternion = pin.Quaternion(pose.rotation)
    return {"position": [float(x) for x in pose.translation],
            "wxyz": [quaternion.w, quaternion.x, quaternion.y, quaternion.z]}


def velocity_joint_names(robot: Robot) -> list[str]:
    """The joint name of each velocity index."""
    model = robot.model
    names = [""] * model.nv
    for joint_id in range(1, model.njoints):
        joint = model.joints[joint_id]
        for k in range(joint.nv):
            names[joint.idx_v + k] = model.names[joint_id]
    return names


def _not_following(record: StepRecord, ee: int = 0) -> bool:
    """Whether EE ``ee`` moves towards its target at less than :data:`FOLLOWING` of the
    commanded speed (or hardly at all): something keeps it from the target."""
    desired = np.asarray(record.commanded_linear_velocities[ee])
    actual = np.asarray(record.actual_linear_velocities[ee])
    speed = float(np.linalg.norm(desired))
    if speed < STALLED_SPEED:
        return float(np.linalg.norm(actual)) < STALLED_SPEED
    return float(actual @ desired) / speed < FOLLOWING * speed


def describe_limitation(info, record: StepRecord | None, distance: float,
                        joint_names: list[str], refused: str = "", ee: int = 0) -> Limitation:
    """In words, what keeps EE ``ee`` (an index of ``robot.ee_frames``) from its target
    (``info`` the controller's last :class:`controllers.SolveInfo`, ``record`` the last
    measured tick, ``distance`` the EE-target distance in m)."""
    status = info.status.value if isinstance(info.status, StepStatus) else str(info.status)
    if refused:
        return Limitation("failed", f"command refused: {refused}", distance)
    if status == "failed":
        return Limitation(status, f"no command: {info.message or 'the controller failed'}",
                          distance)
    if status == "constraint_degraded":
        return Limitation(status, f"constraint degraded: {info.message}", distance)
    parts = []
    if distance > ON_TARGET and record is not None and _not_following(record, ee):
        parts.append("target out of reach")
    if status == "least_squares" and info.message:
        parts.append(f"closest motion: {info.message}")  # it names the joints and the damping
    elif info.saturated_joints:
        names = [joint_names[i] for i in info.saturated_joints]
        parts.append(f"joint {', '.join(names)} at {'its limit' if len(names) == 1 else 'their limits'}")
    elif status == "least_squares":
        parts.append("closest motion")
    if status == "scaled":
        parts.append(f"slowed to {100 * info.scale:.0f} % by the joint limits")
    if not parts:
        parts.append(f"moving to the target ({1e3 * distance:.1f} mm away)"
                     if distance > ON_TARGET else "on target")
    return Limitation(status, "; ".join(parts), distance)


def default_ghost_offset(robot: Robot) -> np.ndarray:
    """Where the ghost goes beside the main robot: sideways from the direction the arms
    reach at home (their EEs' mean), by the robot's width in that direction plus a margin."""
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, robot.q_home)
    points = np.array([frame.translation for frame in data.oMf])
    reach = (np.mean([data.oMf[frame].translation for frame in robot.ee_frame_ids], axis=0)
             - data.oMf[0].translation)
    reach[2] = 0.0
    if np.linalg.norm(reach) < 1e-6:
        reach = np.array([1.0, 0.0, 0.0])
    side = np.cross([0.0, 0.0, 1.0], reach / np.linalg.norm(reach))
    width = float(np.ptp(points @ side))
    return (width + 0.4) * side


class TeleopApp:
    """One robot (plus an optional ghost) teleoperated from one shared set of targets, one
    per end effector.

    Parameters
    ----------
    robot : the robot.
    controller : controller spec of the main robot (``cjm``, ``qp:daqp``, ``mink:daqp``...).
    ghost : spec of a second robot driven from the same target, drawn beside the main
        one (``ghost_offset``), or None.
    rate : control rate (Hz).
    record_dir : the folder session recordings go to; :meth:`start_recording` writes
        there and nowhere else (:class:`web.folders.Folder`).
    scene_dir : the folder scenes are saved to and loaded from, and no other.
    """

    def __init__(self, robot: Robot, controller: str = "cjm", ghost: str | None = None,
                 rate: float = 1000.0, kp: float = 20.0, record_dir: str | Path = "sessions",
                 scene_dir: str | Path = "scenes") -> None:
        rate = as_number(rate, "rate")
        if not MIN_RATE <= rate <= MAX_RATE:
            raise ValueError(f"rate must be between {MIN_RATE:g} and {MAX_RATE:g} Hz, "
                             f"got {rate:g}")
        self.robot = robot
        self._lock = threading.RLock()
        self._build_lock = threading.Lock()  # one loop build at a time (outside _lock)
        self._view_data = robot.model.createData()  # for geometry queries, under the lock
        self.joint_names = velocity_joint_names(robot)
        self.config = LoopConfig(rate=rate, kp=kp, target_time_constant=DEFAULT_SMOOTHING,
                                 max_linear_speed=MAX_LINEAR_SPEED,
                                 max_angular_speed=MAX_ANGULAR_SPEED)
        self.gain = 100.0
        self.damping = 0.0
        #: weight of the EE twists' angular entries (1: full poses; lower lets each
        #: instrument's orientation give way to its tip position, docs/design.md 11.2)
        self.orientation_weight = 1.0
        self.recordings = Folder(record_dir, "recording", ".jsonl")
        self.scenes = Folder(scene_dir, "scene", ".json")
        self.record_dir, self.scene_dir = self.recordings.root, self.scenes.root
        self.entries: dict[str, ConstraintEntry] = {}
        self._ids = itertools.count(1)
        self.specs = {"main": controller}
        self.loops: dict[str, TeleopLoop] = {"main": self._make_loop(controller)}
        self.traces: dict[str, Trace] = {"main": Trace()}
        self.last_records: dict[str, StepRecord | None] = {"main": None}
        self.ghost_offset = default_ghost_offset(robot)
        if ghost:
            self.set_ghost(ghost)
        # the input mapping, per EE: gizmo -> target (clutch, motion scale)
        self.inputs = [EEInput.at(frame, pose) for frame, pose in
                       zip(robot.ee_frames, self.loops["main"].ee_placements())]
        self.motion_scale = 1.0
        self.clutch = False
        self.recorder: SessionRecorder | None = None
        self._record_start = 0.0
        self._next_history = 0.0
        self.ticks = 0

    # -- construction helpers ------------------------------------------------------------

    def _make_loop(self, spec: str, q: np.ndarray | None = None,
                   constraints: list[Constraint] | None = None,
                   config: LoopConfig | None = None,
                   orientation_weight: float | None = None) -> TeleopLoop:
        if constraints is None:
            constraints = [e.constraint for e in getattr(self, "entries", {}).values()]
        config = config or self.config
        weight = self.orientation_weight if orientation_weight is None else orientation_weight
        controller = make_controller(spec, self.robot, constraints, dt=config.dt,
                                     twist_weight=None if weight == 1.0 else
                                     [1.0, 1.0, 1.0, weight, weight, weight])
        self._apply_damping(controller)
        return TeleopLoop(self.robot, controller, q0=q, config=config)

    def _apply_damping(self, controller, damping: float | None = None) -> None:
        if hasattr(controller, "policy"):  # the CJM's damped least squares
            from controllers.linalg import DampingPolicy

            old = controller.policy
            controller.policy = DampingPolicy(self.damping if damping is None else damping,
                                              old.threshold, old.max_damping)

    def _sync_constraints(self) -> None:
        constraints = [e.constraint for e in self.entries.values()]
        for loop in self.loops.values():
            loop.set_constraints(constraints)

    @property
    def now(self) -> float:
        return self.loops["main"].t

    # -- the operator's input: target, gizmo, clutch, motion scale --------------------------

    @property
    def target(self) -> pin.SE3:
        """The first EE's target (``robot.ee_frame``)."""
        return self.inputs[0].target

    @property
    def gizmo(self) -> pin.SE3:
        """The first EE's gizmo pose."""
        return self.inputs[0].gizmo

    @property
    def targets(self) -> list[pin.SE3]:
        """Every EE's target, in ``robot.ee_frames`` order (copies)."""
        with self._lock:
            return [hand.target.copy() for hand in self.inputs]

    def ee_index(self, ee) -> int:
        """``ee`` (an index or a name of ``robot.ee_frames``) as an index; else ``ValueError``."""
        frames = self.robot.ee_frames
        if isinstance(ee, str) and ee in frames:
            return frames.index(ee)
        if isinstance(ee, (int, np.integer)) and not isinstance(ee, bool) and 0 <= ee < len(frames):
            return int(ee)
        raise ValueError(f"no end effector {ee!r}: this robot's are {list(frames)} "
                         f"(or their indices 0-{len(frames) - 1})")

    def _check_target(self, target: pin.SE3, ee: int, what: str = "target") -> None:
        """``ValueError`` when ``target`` is farther than :data:`MAX_TARGET_DISTANCE` from
        where EE ``ee`` of the main robot is now (caller holds the lock)."""
        ee_now = self.loops["main"].ee_placements()[ee].translation
        distance = math.hypot(*(target.translation - ee_now))  # no overflow at 1e300
        if not distance <= MAX_TARGET_DISTANCE:
            raise ValueError(f"{what} refused: {distance:.3g} m from the end effector "
                             f"{self.inputs[ee].frame}, more than {MAX_TARGET_DISTANCE:g} m")

    def _set_target(self, target: pin.SE3, ee: int = 0) -> None:
        """EE ``ee``'s target pose (caller holds the lock); recorded when recording."""
        self.inputs[ee].target = target
        if self.recorder is not None:
            self._record_target(self.now - self._record_start, ee)

    def _record_target(self, t: float, ee: int) -> None:
        """Write EE ``ee``'s target to the session (a single-EE robot's events name no frame)."""
        if len(self.inputs) == 1:
            self.recorder.target(t, self.inputs[0].target)
        else:
            self.recorder.target(t, self.inputs[ee].target, frame=self.inputs[ee].frame)

    def _reanchor(self) -> None:
        """From now on every target moves by its gizmo's motion since this instant."""
        for hand in self.inputs:
            hand.reanchor()

    @staticmethod
    def _pose(position, wxyz, what: str) -> pin.SE3:
        position = as_vector(position, 3, f"{what} position")
        wxyz = as_vector(wxyz, 4, f"{what} quaternion")
        if np.linalg.norm(wxyz) < 1e-9:
            raise ValueError(f"the {what} quaternion must be non-zero")
        rotation = pin.Quaternion(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).normalized().matrix()
        return pin.SE3(rotation, position)

    def set_target(self, position, wxyz, ee=0) -> None:
        """The operator's target pose of EE ``ee`` directly (world position, quaternion
        w, x, y, z). Its gizmo's later motion continues from this target."""
        ee = self.ee_index(ee)
        target = self._pose(position, wxyz, "target")
        with self._lock:
            self._check_target(target, ee)
            self._set_target(target, ee)
            self.inputs[ee].reanchor()

    def move_gizmo(self, position, wxyz, ee=0) -> None:
        """EE ``ee``'s input gizmo pose. Unless the clutch is engaged, its target moves by
        ``motion_scale`` times the gizmo's displacement since the last clutch release
        (and turns with the gizmo's rotation since then); the other targets stay."""
        ee = self.ee_index(ee)
        gizmo = self._pose(position, wxyz, "gizmo")
        with self._lock:
            hand = self.inputs[ee]
            previous, hand.gizmo = hand.gizmo, gizmo
            if not self.clutch:
                target = hand.followed(self.motion_scale)
                try:
                    self._check_target(target, ee, "the gizmo's target")
                except ValueError:
                    hand.gizmo = previous
                    raise
                self._set_target(target, ee)

    def set_clutch(self, engaged: bool) -> None:
        """Engage (the gizmos move alone) or release the clutch; on release every target
        continues from where it is, so none jumps."""
        if not isinstance(engaged, (bool, np.bool_)):
            raise ValueError(f"the clutch is engaged (True) or released (False), got {engaged!r}")
        with self._lock:
            self.clutch = bool(engaged)
            if not self.clutch:
                self._reanchor()

    def set_motion_scale(self, scale: float) -> None:
        """Target displacement per gizmo displacement, in (0, 10], for every gizmo; no
        target jumps."""
        scale = as_number(scale, "motion scale")
        if not 0.0 < scale <= MAX_MOTION_SCALE:
            raise ValueError(f"motion scale must be in (0, {MAX_MOTION_SCALE:g}], got {scale:g}")
        with self._lock:
            self.motion_scale = scale
            self._reanchor()

    def nudge_target(self, displacement, ee=0) -> None:
        """Move EE ``ee``'s target by ``displacement`` (world, m), its gizmo staying where
        it is."""
        ee = self.ee_index(ee)
        displacement = as_vector(displacement, 3, "nudge")
        if np.linalg.norm(displacement) > 0.1:
            raise ValueError("a nudge moves the target by at most 0.1 m")
        with self._lock:
            target = self.inputs[ee].target.copy()
            target.translation = target.translation + displacement
            self._check_target(target, ee, "nudged target")
            self._set_target(target, ee)
            self.inputs[ee].reanchor()

    def hold_where_the_robot_is(self, ee=None) -> None:
        """Every target and gizmo (or EE ``ee``'s) on the main robot's EE pose now: what a
        browser lost mid-drag leaves behind (docs/design.md section 5.3). The robot then
        settles where it is instead of going on towards the last point of the drag,
        which may lie past a joint limit."""
        indices = range(len(self.inputs)) if ee is None else [self.ee_index(ee)]
        with self._lock:
            placements = self.loops["main"].ee_placements()
            for index in indices:
                hand = self.inputs[index]
                self._set_target(placements[index].copy(), index)
                hand.gizmo = hand.target.copy()
                hand.reanchor()

    def gizmo_to_target(self, ee=0) -> pin.SE3:
        """Put EE ``ee``'s gizmo on its target (the UI moves its handle there); returns
        the pose."""
        ee = self.ee_index(ee)
        with self._lock:
            hand = self.inputs[ee]
            hand.gizmo = hand.target.copy()
            hand.reanchor()
            return hand.gizmo.copy()

    # -- constraints ---------------------------------------------------------------------

    def _link_placement(self, link: str, which: str = "main") -> pin.SE3:
        """World placement of ``link`` on robot ``which`` now (caller holds the lock)."""
        return frame_placement(self.robot.model, self.loops[which].q, link, self._view_data)

    def add_constraint(self, constraint: Constraint, entry_id: str | None = None,
                       goal: np.ndarray | None = None) -> str:
        """Place a constraint of any kind where it is; it takes the app's drift gain.

        Returns its id (``"<kind>-<n>"``). A constraint the controllers refuse (unknown
        link, gain unstable at this rate) raises ``ValueError`` and is not placed.
        """
        if not isinstance(constraint, Constraint):
            raise ValueError(f"expected a constraint, got {constraint!r}")
        with self._lock:
            constraint.gain = self.gain
            entry_id = entry_id or f"{constraint.kind}-{next(self._ids)}"
            if entry_id in self.entries:
                raise ValueError(f"a constraint {entry_id!r} is already placed")
            goal = constraint.position if goal is None else np.asarray(goal, dtype=float).copy()
            self.entries[entry_id] = ConstraintEntry(
                entry_id, constraint, goal, settled=bool(np.array_equal(goal, constraint.position)))
            try:
                self._sync_constraints()
            except ValueError:
                del self.entries[entry_id]
                self._sync_constraints()
                raise
            if self.recorder is not None:
                self.recorder.add(self.now - self._record_start, entry_id, constraint)
            return entry_id

    @property
    def plane_links(self) -> tuple[str, ...]:
        """The links a plane or barrier may hold: the constrained links (one per arm)
        first, then every other link that moves (a mobile base's ``mobile_base``...)."""
        model = self.robot.model
        moving = [frame.name for frame in model.frames
                  if frame.type == pin.FrameType.BODY and frame.parentJoint != 0]
        return tuple(dict.fromkeys((*self.robot.constrained_links, *moving)))

    def _arm_ee(self, link: str) -> str:
        """The EE frame on ``link``'s arm: the first whose chain carries the link (a link
        before every arm, such as the torso or a mobile base, gives the first EE)."""
        model = self.robot.model
        joint = model.frames[model.getFrameId(link)].parentJoint
        return next((frame for frame in self.robot.ee_frames
                     if joint in model.supports[model.frames[model.getFrameId(frame)].parentJoint]),
                    self.robot.ee_frame)

    def _constrained_link(self, link: str | None, what: str) -> str:
        """``link`` (default: the first constrained link) if it carries an instrument
        axis (``robot.link_axes``); else ``ValueError`` naming the ones that do."""
        links = self.robot.constrained_links
        if not links:
            raise ValueError(f"this robot has no constrained link: start `teleop web` with "
                             f"--constrained-link LINK (and --link-axis X Y Z) to place a {what}")
        link = links[0] if link is None else link
        if link not in links:
            raise ValueError(f"a {what} goes on a constrained link: one of {list(links)}, "
                             f"got {link!r}")
        return link

    def _link_distance(self, distance: float, what: str, link: str) -> float:
        """``distance`` (m along ``link``'s axis) if it lies on the arm: between the link's
        joint (0) and the distance of that arm's EE from it; else ``ValueError``."""
        distance = as_number(distance, what)
        with self._lock:
            placement = self._link_placement(link)
            reach = float(np.linalg.norm(placement.actInv(
                self._link_placement(self._arm_ee(link)).translation)))
        if not 0.0 <= distance <= reach:
            raise ValueError(f"{what} must be between 0 and {reach:.3f} m (from the joint of "
                             f"{link} to the tool tip), got {distance:g} m")
        return distance

    def add_hole(self, distance: float, link: str | None = None) -> str:
        """A hole on ``link`` (default: the first constrained link), ``distance`` m along
        its axis (``robot.link_axes[link]``), where it is now."""
        link = self._constrained_link(link, "hole")
        distance = self._link_distance(distance, "hole distance", link)
        with self._lock:
            return self.add_constraint(Hole.on_link(self.robot, self.loops["main"].q,
                                                    distance=distance, link=link))

    def add_point_lock(self, distance: float, link: str | None = None) -> str:
        """Lock the point ``distance`` m along ``link``'s axis (default: the first
        constrained link) where it is now."""
        link = self._constrained_link(link, "point lock")
        distance = self._link_distance(distance, "point lock distance", link)
        with self._lock:
            return self.add_constraint(PointLock.on_link(self.robot, self.loops["main"].q,
                                                         distance=distance, link=link))

    def add_plane(self, distance: float | None, normal, barrier: bool = False,
                  offset: float = 0.0, link: str | None = None, link_point=None) -> str:
        """A plane (or barrier) through a point of ``link`` (default: the first
        constrained link) as it is now: ``distance`` m along the link's axis on a
        constrained link, else ``link_point`` (link coordinates, m; e.g. a corner of a
        mobile base, kept off a wall by a barrier).

        ``normal`` is a direction in **world** coordinates (normalised here; zero is
        refused); a barrier's allowed side is the one it points to. A barrier may sit
        ``offset`` m below the point along the normal (the point must be on its positive
        side).
        """
        what = "barrier" if barrier else "plane"
        if link is None:
            link = self._constrained_link(None, what)
        if link not in self.plane_links:
            raise ValueError(f"no link {link!r} to put a {what} on: one of {list(self.plane_links)}")
        if link in self.robot.link_axes:
            if link_point is not None:
                raise ValueError(f"a {what} on {link} goes through a point on its axis: give "
                                 "its distance, not a link point")
            distance = self._link_distance(distance, "plane distance", link)
            at = {"distance": distance}
        else:
            if link_point is None:
                raise ValueError(f"{link} has no instrument axis: give the {what}'s point on "
                                 "it in link coordinates (m)")
            link_point = as_vector(link_point, 3, f"{what} link point")
            if np.linalg.norm(link_point) > MAX_LINK_POINT:
                raise ValueError(f"the {what}'s link point must be within {MAX_LINK_POINT:g} m "
                                 f"of {link}'s origin")
            at = {"link_point": link_point}
        offset = as_number(offset, "barrier offset")
        normal = as_vector(normal, 3, "plane normal")
        if np.linalg.norm(normal) < 1e-9:
            raise ValueError("the plane normal must be a non-zero 3-vector")
        normal = normal / np.linalg.norm(normal)
        with self._lock:
            q = self.loops["main"].q
            point = self._link_placement(link).act(
                at["link_point"] if "link_point" in at
                else at["distance"] * np.asarray(self.robot.link_axes[link]))
            cls = Barrier if barrier else Plane
            constraint = cls.through_link_point(self.robot, q, normal=normal, link=link,
                                                plane_point=point - offset * normal, **at)
            return self.add_constraint(constraint)

    def move_constraint(self, entry_id: str, position) -> None:
        """Move a constraint's geometry (hole centre, plane point, lock target): the robot
        follows it."""
        position = as_vector(position, 3, "constraint position")
        with self._lock:
            if entry_id not in self.entries:
                raise ValueError(f"no constraint {entry_id!r}")
            entry = self.entries[entry_id]
            distance = math.hypot(*(position - entry.position))
            if distance > MAX_TARGET_DISTANCE:
                raise ValueError(f"constraint position refused: {distance:.3g} m from where "
                                 f"{entry_id} is, more than {MAX_TARGET_DISTANCE:g} m")
            entry.goal = position.copy()
            entry.settled = False

    def remove_constraint(self, entry_id: str) -> None:
        with self._lock:
            if self.entries.pop(entry_id, None) is None:
                raise ValueError(f"no constraint {entry_id!r}")
            self._sync_constraints()
            if self.recorder is not None:
                self.recorder.remove(self.now - self._record_start, entry_id)

    def clear_constraints(self) -> int:
        """Remove every constraint; how many there were."""
        with self._lock:
            ids = list(self.entries)
            for entry_id in ids:
                self.remove_constraint(entry_id)
            return len(ids)

    # -- controllers and settings ----------------------------------------------------------
    #
    # A new controller, rate or orientation weight needs new loops: they are built outside
    # the lock (milliseconds of work) and swapped in under it, so the control thread does
    # not wait for a build (docs/design.md section 5.3).

    def _build_inputs(self) -> tuple:
        """What a loop build reads besides its own arguments: if any of it changed while
        a build ran outside the lock, the build is redone under the lock."""
        return (tuple(id(e.constraint) for e in self.entries.values()), self.gain,
                self.damping, self.config, self.orientation_weight, tuple(self.specs.items()))

    def _rebuild(self, specs: dict[str, str], config: LoopConfig | None = None,
                 orientation_weight: float | None = None) -> None:
        """Robots ``specs`` (``{"main": spec, "ghost": spec}``) with new loops at ``config``
        and ``orientation_weight`` (default: the current ones), each starting from the
        state of the loop it replaces (a new ghost from the main robot's); the others keep
        theirs. All or nothing: a spec or gain that cannot be built raises ``ValueError``
        and changes nothing."""
        with self._build_lock:
            with self._lock:
                inputs = self._build_inputs()
                config = config or self.config
                weight = self.orientation_weight if orientation_weight is None \
                    else orientation_weight
                constraints = [e.constraint for e in self.entries.values()]
                starts = {which: self.loops.get(which, self.loops["main"]).q.copy()
                          for which in specs}
            loops = {which: self._make_loop(spec, q=starts[which], constraints=constraints,
                                            config=config, orientation_weight=weight)
                     for which, spec in specs.items()}  # raises ValueError: nothing changed
            with self._lock:
                if self._build_inputs() != inputs:  # changed meanwhile: build it again here
                    constraints = [e.constraint for e in self.entries.values()]
                    loops = {which: self._make_loop(spec, constraints=constraints,
                                                    config=config, orientation_weight=weight)
                             for which, spec in specs.items()}
                for which, loop in loops.items():  # the state they replace, as of now
                    old = self.loops.get(which, self.loops["main"])
                    loop.q = old.q.copy()
                    loop.t = old.t
                if config is not self.config:  # every other loop follows the new period
                    others = {which: self._make_loop(self.specs[which], q=loop.q.copy(),
                                                     constraints=constraints, config=config,
                                                     orientation_weight=weight)
                              for which, loop in self.loops.items() if which not in loops}
                    for which, loop in others.items():
                        loop.t = self.loops[which].t
                    loops.update(others)
                for which in loops:
                    if which not in self.traces:
                        self.traces[which] = Trace()
                        self.last_records[which] = None
                self.config, self.orientation_weight = config, weight
                self.specs.update(specs)
                self.loops.update(loops)

    def set_controller(self, spec: str) -> None:
        """Switch the main robot's controller, keeping its state."""
        self._rebuild({"main": spec})

    def set_ghost(self, spec: str | None) -> None:
        """Show a second robot driven by ``spec`` from the same target (None removes it).

        It starts where the main robot is, at the same time, so the two histories line up.
        """
        if not spec:
            with self._lock:
                for store in (self.loops, self.specs, self.traces, self.last_records):
                    store.pop("ghost", None)
            return
        self._rebuild({"ghost": spec})

    def set_ghost_offset(self, offset) -> None:
        """Where the ghost is drawn, from the main robot (world, m); zero overlays them."""
        offset = as_vector(offset, 3, "ghost offset")
        if np.linalg.norm(offset) > MAX_GHOST_OFFSET:
            raise ValueError(f"the ghost offset must be at most {MAX_GHOST_OFFSET:g} m long, "
                             f"got {np.linalg.norm(offset):.3g} m")
        with self._lock:
            self.ghost_offset = offset

    def set_gain(self, gain: float) -> None:
        """Gain K (1/s) of every constraint: the drift feedback of the equalities, the
        approach rate of the barriers, in [0, 2 / dt) (``K dt`` at most 2). A gain some
        placed constraint cannot take at this rate raises ``ValueError`` naming the gain
        and changes nothing."""
        gain = as_number(gain, "gain")
        with self._lock:
            if not 0.0 <= gain * self.config.dt < 2.0:
                raise ValueError(f"gain must be in [0, {2.0 / self.config.dt:g}) 1/s at this "
                                 f"rate, got {gain:g}")
            previous = self.gain
            try:  # each constraint checks the gain at its controllers' period
                for entry in self.entries.values():
                    entry.constraint.gain = gain
                self.gain = gain
                self._sync_constraints()
            except ValueError:
                self.gain = previous
                for entry in self.entries.values():
                    entry.constraint.gain = previous
                self._sync_constraints()
                raise

    def set_damping(self, damping: float) -> None:
        """Constant DLS damping lambda of the CJM (paper eq 35), in [0, MAX_DAMPING]."""
        damping = as_number(damping, "damping", 0.0, maximum=MAX_DAMPING)
        with self._lock:
            self.damping = damping
            for loop in self.loops.values():
                self._apply_damping(loop.controller)

    def set_orientation_weight(self, weight: float) -> None:
        """Weight in [0, 1] of every EE twist's angular entries against the linear ones
        (every controller's ``twist_weight``): 1 asks for full poses; with two trocars on
        one torso, which leave 11 joint directions for 12 entries, a lower weight lets the
        orientations give way so the tips go where they are dragged. Rebuilds the loops,
        keeps the state."""
        weight = as_number(weight, "orientation weight", 0.0, maximum=1.0)
        self._rebuild(dict(self.specs), orientation_weight=weight)

    def set_rate(self, rate: float) -> None:
        """Control rate (Hz), in [MIN_RATE, MAX_RATE]; rebuilds the loops (QP limits depend
        on dt), keeps the state."""
        rate = as_number(rate, "rate")
        if not MIN_RATE <= rate <= MAX_RATE:
            raise ValueError(f"rate must be between {MIN_RATE:g} and {MAX_RATE:g} Hz, "
                             f"got {rate:g}")
        self._rebuild(dict(self.specs), config=dataclasses.replace(self.config, rate=rate))

    def home(self, ee=None) -> None:
        """Every target and gizmo (or only EE ``ee``'s) on its home EE pose. The
        constraints stay (:meth:`clear_constraints` removes them), so the robots drive
        there through their controllers, the constraints held; homing every EE with no
        constraint placed also puts the robots back at ``q_home`` at once (a reset)."""
        indices = range(len(self.inputs)) if ee is None else [self.ee_index(ee)]
        with self._lock:
            if ee is None and not self.entries:
                for loop in self.loops.values():
                    t = loop.t
                    loop.reset()
                    loop.t = t
            pin.framesForwardKinematics(self.robot.model, self._view_data, self.robot.q_home)
            for index in indices:
                hand = self.inputs[index]
                self._set_target(self._view_data.oMf[self.robot.ee_frame_ids[index]].copy(), index)
                hand.gizmo = hand.target.copy()
                hand.reanchor()

    # -- scenes ----------------------------------------------------------------------------

    def scene(self) -> dict:
        """The scene as a JSON-ready dict (format in :mod:`web.scene`)."""
        with self._lock:
            targets = [_pose_to_dict(hand.target) for hand in self.inputs]
            several = {} if len(targets) == 1 else {"targets": [
                {"frame": hand.frame, **pose} for hand, pose in zip(self.inputs, targets)]}
            return {
                "format": SCENE_FORMAT, "version": SCENE_VERSION,
                "created": datetime.now().isoformat(timespec="seconds"),
                "robot": robot_to_dict(self.robot),
                "controllers": {"main": self.specs["main"], "ghost": self.specs.get("ghost")},
                "gain": self.gain, "damping": self.damping, "rate": self.config.rate,
                "orientation_weight": self.orientation_weight,
                "motion_scale": self.motion_scale,
                "ghost_offset": [float(x) for x in self.ghost_offset],
                "q": {which: [float(x) for x in loop.q] for which, loop in self.loops.items()},
                "target": targets[0], **several,
                "constraints": [{"id": e.id, "goal": [float(x) for x in e.goal],
                                 "constraint": e.constraint.to_dict()}
                                for e in self.entries.values()],
            }

    def save_scene(self, name: str | None = None) -> Path:
        """Write the scene as file ``name`` of the scene folder (default: a new name);
        its path. A name that is not a plain file name of that folder is refused
        (:class:`web.folders.Folder`)."""
        if name is None or isinstance(name, str) and not name.strip():
            name = self.scenes.unused_name(f"scene-{datetime.now():%Y%m%d-%H%M%S}")
        return write_scene_file(self.scenes.writable(name), self.scene())

    def load_scene(self, name: str) -> None:
        """Read file ``name`` of the scene folder and apply it (:meth:`apply_scene`)."""
        self.apply_scene(read_scene_file(self.scenes.existing(name)))

    def apply_scene(self, data: dict) -> None:
        """Put the app in the state a scene describes: robots' configurations, constraints,
        target, controllers, gain, damping, rate, motion scale, ghost offset. All or
        nothing: a scene that cannot be applied raises ``ValueError`` and changes nothing.
        The scene must be for this robot (another robot needs ``teleop web --scene``)."""
        scene = parse_scene(data, self.robot.model.nq, self.robot.ee_frames)
        if not same_robot(self.robot, scene.robot):
            raise ValueError(f"this scene is for robot {scene.robot.get('source')!r}, this UI "
                             f"runs {robot_source(self.robot)!r}: start "
                             "`teleop web --scene FILE` to open it with its robot")
        model = self.robot.model
        for which, q in scene.q.items():
            outside = np.flatnonzero((q < model.lowerPositionLimit - 1e-9)
                                     | (q > model.upperPositionLimit + 1e-9))
            if outside.size:
                raise ValueError(f"scene q.{which} is outside the joint limits of "
                                 f"{[self.joint_names[i] for i in outside]}")
        if not MIN_RATE <= scene.rate <= MAX_RATE:
            raise ValueError(f"scene rate must be between {MIN_RATE:g} and {MAX_RATE:g} Hz")
        if scene.damping > MAX_DAMPING:
            raise ValueError(f"scene damping must be at most {MAX_DAMPING:g}")
        data = model.createData()
        for index, (position, _) in enumerate(scene.targets):
            ee = frame_placement(model, scene.q["main"], self.robot.ee_frame_ids[index], data)
            if not math.hypot(*(position - ee.translation)) <= MAX_TARGET_DISTANCE:
                raise ValueError(f"scene target of {self.robot.ee_frames[index]} is more than "
                                 f"{MAX_TARGET_DISTANCE:g} m from its end effector")
        if not 0.0 < scene.motion_scale <= MAX_MOTION_SCALE:
            raise ValueError(f"scene motion_scale must be in (0, {MAX_MOTION_SCALE:g}]")
        if np.linalg.norm(scene.ghost_offset) > MAX_GHOST_OFFSET:
            raise ValueError(f"scene ghost_offset must be at most {MAX_GHOST_OFFSET:g} m long")
        constraints = [placed.constraint for placed in scene.constraints]
        for constraint in constraints:
            constraint.gain = scene.gain
        config = dataclasses.replace(self.config, rate=scene.rate)
        with self._lock:
            t = self.now
            specs = {"main": scene.main, **({"ghost": scene.ghost} if scene.ghost else {})}
            loops = {}
            for which, spec in specs.items():  # raises ValueError: nothing changed yet
                loop = self._make_loop(spec, q=scene.q[which], constraints=constraints,
                                       config=config,
                                       orientation_weight=scene.orientation_weight)
                self._apply_damping(loop.controller, scene.damping)
                loop.t = t
                loops[which] = loop
            self.config, self.gain, self.damping = config, scene.gain, scene.damping
            self.orientation_weight = scene.orientation_weight
            self.specs, self.loops = specs, loops
            self.traces = {which: Trace() for which in loops}
            self.last_records = {which: None for which in loops}
            self.entries = {}
            for placed in scene.constraints:
                self.entries[placed.id] = ConstraintEntry(
                    placed.id, placed.constraint, placed.goal.copy(),
                    settled=bool(np.array_equal(placed.goal, placed.constraint.position)))
            numbers = [int(p.id.rsplit("-", 1)[1]) for p in scene.constraints
                       if p.id.rsplit("-", 1)[-1].isdigit()]
            self._ids = itertools.count(max(numbers, default=0) + 1)
            self.ghost_offset = scene.ghost_offset.copy()
            self.motion_scale = scene.motion_scale
            self.clutch = False
            for index, (position, wxyz) in enumerate(scene.targets):
                self._set_target(self._pose(position, wxyz, "target"), index)
                self.inputs[index].gizmo = self.inputs[index].target.copy()
            self._reanchor()
            self._next_history = t

    # -- recording ---------------------------------------------------------------------

    def start_recording(self, name: str | None = None) -> Path:
        """Record the session to file ``name`` of the recording folder (default: a new
        name, by date); its path. A name already in the folder is refused: a recording
        never replaces another."""
        with self._lock:
            if self.recorder is not None:
                raise ValueError(f"already recording to {self.recorder.path.name}")
            if name is None:
                name = self.recordings.unused_name(f"session-{datetime.now():%Y%m%d-%H%M%S}")
            path = self.recordings.new(name)
            self.recorder = SessionRecorder(path, self.robot, self.loops["main"].q,
                                            rate_hz=self.config.rate, kp=self.config.kp,
                                            target_time_constant_s=self.config.target_time_constant)
            self._record_start = self.now
            for entry in self.entries.values():
                self.recorder.add(0.0, entry.id, entry.constraint)
            for index in range(len(self.inputs)):
                self._record_target(0.0, index)
            return self.recorder.path

    def stop_recording(self) -> Path:
        with self._lock:
            if self.recorder is None:
                raise ValueError("not recording")
            recorder, self.recorder = self.recorder, None
            recorder.close(self.now - self._record_start)
            return recorder.path

    # -- the control tick ------------------------------------------------------------------

    def step(self) -> float:
        """One control period for every robot (called by the control thread); returns the
        time the controllers took (us).

        Every tick computes what the controllers need; the measures of the live plots and
        the status (constraint errors, EE error, ...) are taken on the history ticks only
        (:data:`HISTORY_RATE`).
        """
        with self._lock:
            dt = self.config.dt
            moving = [entry for entry in self.entries.values() if not entry.settled]
            if moving:
                self._steer(moving, dt)
            targets, start = [hand.target for hand in self.inputs], self.now
            if start >= self._next_history - 0.5 * dt:
                solve_us = self._measured_step(targets, moving, dt)
                self._next_history = start + 1.0 / HISTORY_RATE
            else:
                solve_us = 0.0
                for loop in self.loops.values():  # the hot path only (no measures)
                    solve_us += loop.advance(targets).step_time_us
                for entry in moving:  # where the period took the geometry
                    advance(entry.constraint, dt)
            self.ticks += 1
            return solve_us

    def _steer(self, moving: list[ConstraintEntry], dt: float) -> None:
        """Moved geometry glides towards its goal, with feed-forward; settles there."""
        alpha = 1.0 - math.exp(-dt / self.config.target_time_constant)
        for entry in moving:
            constraint = entry.constraint
            if float(np.linalg.norm(entry.goal - constraint.position)) < 1e-12:
                constraint.move_to(entry.goal, (0.0, 0.0, 0.0))
                entry.settled = True
                continue
            steer(constraint, entry.goal, dt, smoothing=alpha)
            if (self.recorder is not None and self.ticks % 10 == 0
                    and np.any(constraint.velocity)):
                self.recorder.move(self.now - self._record_start, entry.id,
                                   constraint.position, constraint.velocity)

    def _measured_step(self, targets: list[pin.SE3], moving: list[ConstraintEntry],
                       dt: float) -> float:
        """A full tick with the measures, appended to the history."""
        pending = {which: loop.advance(targets) for which, loop in self.loops.items()}
        for which, loop in self.loops.items():  # before the geometry moves on
            loop.measure_command(pending[which])
        for entry in moving:
            advance(entry.constraint, dt)
        main_qd = self.loops["main"].last_qd
        for which, loop in self.loops.items():
            record = loop.measure(pending[which])
            self.last_records[which] = record
            deviation = 0.0 if which == "main" else float(np.linalg.norm(loop.last_qd - main_qd))
            self.traces[which].add(record, deviation)
        return sum(step.step_time_us for step in pending.values())

    # -- what the view draws -----------------------------------------------------------

    def limitation(self, which: str = "main", ee=0) -> Limitation:
        """What keeps EE ``ee`` of robot ``which`` from its target now, in words
        (:func:`describe_limitation`)."""
        ee = self.ee_index(ee)
        with self._lock:
            loop = self.loops[which]
            placement = frame_placement(self.robot.model, loop.q, self.robot.ee_frame_ids[ee],
                                        self._view_data)
            return self._limitation(which, placement, ee)

    def _limitation(self, which: str, placement: pin.SE3, ee: int) -> Limitation:
        loop = self.loops[which]
        distance = float(np.linalg.norm(placement.translation
                                        - self.inputs[ee].target.translation))
        return describe_limitation(loop.controller.info, self.last_records.get(which),
                                   distance, self.joint_names, loop.refused, ee)

    def active_barriers(self, which: str = "main") -> list[str]:
        """Ids of the barriers robot ``which``'s controller holds as equalities now."""
        with self._lock:
            controller = self.loops[which].controller
            ids = {id(e.constraint): e.id for e in self.entries.values()}
            constraints = controller.constraints
            return [ids.get(id(constraints[i]), f"#{i}") for i in controller.info.active_barriers
                    if i < len(constraints)]

    def snapshot(self, history: bool = True) -> dict:
        """A consistent copy of everything the view shows (``history``: with the plots'
        data)."""
        with self._lock:
            model = self.robot.model
            robots = {}
            axes = self.robot.link_axes
            for which, loop in self.loops.items():
                q = loop.q.copy()
                pin.framesForwardKinematics(model, self._view_data, q)
                placements = self._view_data.oMf
                constraints = {}
                for entry in self.entries.values():
                    link = model.getFrameId(entry.constraint.link)
                    placement = placements[link]
                    axis = axes.get(entry.constraint.link)
                    constraints[entry.id] = {
                        "geometry": entry.constraint.geometry(placement),
                        "link": entry.constraint.link, "link_placement": placement.copy(),
                        "link_axis": None if axis is None else placement.rotation @ axis}
                ees = [placements[frame].copy() for frame in self.robot.ee_frame_ids]
                limitations = [self._limitation(which, ee, index) for index, ee in enumerate(ees)]
                robots[which] = {
                    "spec": self.specs[which], "q": q, "t": loop.t,
                    "ees": ees, "ee": ees[0],  # every EE, the first
                    "record": self.last_records.get(which),
                    "trace": self.traces[which].arrays() if history else None,
                    "info": loop.controller.info, "constraints": constraints,
                    "limitations": limitations, "limitation": limitations[0],
                    "active_barriers": self.active_barriers(which),
                }
            entries = [{"id": entry.id, "kind": entry.kind, "goal": entry.goal.copy(),
                        **robots["main"]["constraints"][entry.id]}  # geometry, link_axis
                       for entry in self.entries.values()]
            return {"robots": robots, "constraints": entries,
                    "ee_frames": self.robot.ee_frames,
                    "targets": [hand.target.copy() for hand in self.inputs],
                    "gizmos": [hand.gizmo.copy() for hand in self.inputs],
                    "target": self.target.copy(), "gizmo": self.gizmo.copy(),
                    "clutch": self.clutch, "motion_scale": self.motion_scale,
                    "ghost_offset": self.ghost_offset.copy(),
                    "recording": self.recorder is not None,
                    "config": self.config, "gain": self.gain, "damping": self.damping}


#: ticks of timing kept by the control thread (a few seconds at 1 kHz)
TIMING_WINDOW = 4096
#: the control thread asks the interpreter to switch threads this often (s): a thread
#: waking for its deadline waits at most about this long for the others (Python's default
#: 5 ms would make the 1 kHz loop late by up to 5 periods whenever the view thread works)
SWITCH_INTERVAL = 2e-4


#: the control loop is behind when it achieves less than this fraction of its rate
BEHIND_FRACTION = 0.95


def behind_words(achieved_rate: float, rate: float) -> str:
    """The operator's warning when a loop asked for ``rate`` (Hz) achieves less than
    :data:`BEHIND_FRACTION` of it over the last second, else ``""``: the robot then moves
    slower than commanded and the measures stretch in time (docs/design.md section 5.3)."""
    if achieved_rate >= BEHIND_FRACTION * rate:
        return ""
    return (f"control loop behind: only {achieved_rate:.0f} of the {rate:.0f} Hz asked for "
            f"({100.0 * achieved_rate / rate:.0f} %); this machine is too busy for this rate")


@dataclass(frozen=True)
class Timing:
    """The control thread's timing over its last :data:`TIMING_WINDOW` ticks."""

    achieved_rate: float  # Hz, over the last second
    lateness_p50_ms: float  # how late a tick starts after its deadline
    lateness_p99_ms: float
    tick_p50_us: float  # the whole tick (TeleopApp.step)
    tick_p99_us: float
    overhead_p50_us: float  # the tick minus the controllers' own solve time
    deadline_misses: int
    ticks: int


class ControlThread:
    """Runs :meth:`TeleopApp.step` at the app's control rate on its own thread.

    Tracks the achieved rate, each tick's lateness (start minus deadline) and cost, and
    deadline misses (a tick that started later than one period after it was due). Sleeps
    between ticks; when it falls behind it does not try to catch up by bursting (the robot
    would see a jump), it resynchronises.
    """

    def __init__(self, app: TeleopApp) -> None:
        self.app = app
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="control", daemon=True)
        self.deadline_misses = 0
        self.achieved_rate = 0.0
        self._measured_rate: float | None = None  # the rate the last full second ran at
        self.error: str | None = None
        self._lateness = np.zeros(TIMING_WINDOW)
        self._tick = np.zeros(TIMING_WINDOW)
        self._solve = np.zeros(TIMING_WINDOW)
        self._count = 0
        self._switch_interval: float | None = None

    def start(self) -> None:
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(min(self._switch_interval, SWITCH_INTERVAL))
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        self._thread.join(timeout)
        if self._switch_interval is not None:
            sys.setswitchinterval(self._switch_interval)
            self._switch_interval = None

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def behind(self) -> str:
        """:func:`behind_words` for the last full second at the current rate (``""``
        before one has been measured)."""
        rate = 1.0 / self.app.config.dt
        if self._measured_rate is None or self._measured_rate != rate:
            return ""
        return behind_words(self.achieved_rate, rate)

    def timing(self) -> Timing:
        """Percentiles of the recent ticks (computed here, off the control thread)."""
        n = min(self._count, TIMING_WINDOW)
        if n == 0:
            return Timing(self.achieved_rate, math.nan, math.nan, math.nan, math.nan,
                          math.nan, self.deadline_misses, 0)
        lateness, tick, solve = self._lateness[:n].copy(), self._tick[:n].copy(), self._solve[:n].copy()
        return Timing(
            achieved_rate=self.achieved_rate,
            lateness_p50_ms=1e3 * float(np.percentile(lateness, 50)),
            lateness_p99_ms=1e3 * float(np.percentile(lateness, 99)),
            tick_p50_us=1e6 * float(np.percentile(tick, 50)),
            tick_p99_us=1e6 * float(np.percentile(tick, 99)),
            overhead_p50_us=float(np.percentile(1e6 * tick - solve, 50)),
            deadline_misses=self.deadline_misses, ticks=self._count)

    def _run(self) -> None:
        clock = time.perf_counter
        next_tick = clock()
        window_start, window_ticks = clock(), 0
        period = self.app.config.dt
        while not self._stop.is_set():
            if self.app.config.dt != period:  # a new rate: a new measuring window
                period = self.app.config.dt
                window_start, window_ticks = clock(), 0
            start = clock()
            solve_us = 0.0
            try:
                solve_us = self.app.step()
            except Exception as error:  # keep the robot still and say why
                self.error = f"{type(error).__name__}: {error}"
                time.sleep(0.01)
            end = clock()
            slot = self._count % TIMING_WINDOW
            self._lateness[slot] = max(0.0, start - next_tick)
            self._tick[slot] = end - start
            self._solve[slot] = solve_us
            self._count += 1
            window_ticks += 1
            if end - window_start >= 1.0:
                self.achieved_rate = window_ticks / (end - window_start)
                self._measured_rate = 1.0 / period
                window_start, window_ticks = end, 0
            next_tick += period
            delay = next_tick - clock()
            if delay > 0:
                time.sleep(delay)
            elif delay < -period:
                self.deadline_misses += 1
                next_tick = clock()
