"""The operator's console: per end effector a target and an input gizmo, the clutch, the
motion scale, nudges and home (docs/design.md section 5.3).

As on a surgical or industrial console, a **clutch** decouples the gizmos from the
targets, and **motion scaling** maps each gizmo displacement ``d`` to a target
displacement ``scale d`` (orientation follows the gizmo's rotation, unscaled): the
gizmo is an input source in the world's frame, mapped as every device is
(:func:`teleop.inputs.followed_pose`, docs/design.md section 19.1), so the clutch and a
new motion scale never make a target jump. A robot with several end effectors
(docs/design.md section 11) has a target and a gizmo per EE (:class:`EEInput`); the actions take
the EE's index ``ee``
(0: ``robot.ee_frame``). The clutch and the motion scale are shared by every gizmo; each
gizmo moves its own target.
"""

from __future__ import annotations

import copy
import math
import threading
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from constraints.validation import as_number, as_vector
from teleop.inputs import followed_pose
from teleop.robots import Robot

from .editing import ConstraintEditing
from .end_effectors import ee_index
from .limits import MAX_MOTION_SCALE, MAX_TARGET_DISTANCE
from .homing import WayHome
from .recording import SessionRecording
from .robots import Robots
from .ros2_robot import Ros2Robot

#: a nudge moves a target by at most this much (m)
MAX_NUDGE = 0.1


@dataclass
class EEInput:
    """The operator's input for one end effector: its target and its gizmo."""

    frame: str  # the EE frame (an entry of robot.ee_frames)
    target: pin.SE3
    gizmo: pin.SE3

    @classmethod
    def at(cls, frame: str, pose: pin.SE3) -> "EEInput":
        """Target and gizmo both at ``pose``."""
        return cls(frame, pose.copy(), pose.copy())


def pose_from(position, wxyz, what: str) -> pin.SE3:
    """A pose from a world position and a quaternion (w, x, y, z), normalised; a bad or
    zero one raises ``ValueError`` naming ``what``."""
    position = as_vector(position, 3, f"{what} position")
    wxyz = as_vector(wxyz, 4, f"{what} quaternion")
    if np.linalg.norm(wxyz) < 1e-9:
        raise ValueError(f"the {what} quaternion must be non-zero")
    rotation = pin.Quaternion(wxyz[0], wxyz[1], wxyz[2], wxyz[3]).normalized().matrix()
    return pin.SE3(rotation, position)


class Console:
    """The operator's console of :class:`web.app.TeleopApp` (``app.console``), a component
    that owns it: per EE the target and the gizmo (:attr:`inputs`), the :attr:`clutch`
    and the :attr:`motion_scale`. Its actions take the session's lock; the control tick
    reads :attr:`inputs` holding it.

    Parameters
    ----------
    robot : the session's robot.
    lock : the session's lock.
    robots : the session's robots (the targets are checked against the main one's EEs;
        "Home" resets their loops).
    constraints : the placed constraints (with some, "Home" follows a joint path).
    homing : the way home.
    recorder : the session's recording (it gets every target).
    ros2 : the robot over ROS 2 (it cannot jump home), or None.
    """

    def __init__(self, robot: Robot, lock: threading.RLock, robots: Robots,
                 constraints: ConstraintEditing, homing: WayHome, recorder: SessionRecording,
                 ros2: Ros2Robot | None) -> None:
        self.robot = robot
        self._lock = lock
        self._robots = robots
        self._constraints = constraints
        self._homing = homing
        self._recorder = recorder
        self._ros2 = ros2
        self._data = robot.model.createData()  # for the home poses, under the lock
        # the input mapping, per EE: gizmo -> target (clutch, motion scale)
        self.inputs = [EEInput.at(frame, pose) for frame, pose in
                       zip(robot.ee_frames, robots.loops["main"].ee_placements())]
        self.motion_scale = 1.0
        self.clutch = False

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

    def _check_target(self, target: pin.SE3, ee: int, what: str = "target") -> None:
        """``ValueError`` when ``target`` is farther than :data:`MAX_TARGET_DISTANCE` from
        where EE ``ee`` of the main robot is now (caller holds the lock)."""
        ee_now = self._robots.loops["main"].ee_placements()[ee].translation
        distance = math.hypot(*(target.translation - ee_now))  # no overflow at 1e300
        if not distance <= MAX_TARGET_DISTANCE:
            raise ValueError(f"{what} refused: {distance:.3g} m from the end effector "
                             f"{self.inputs[ee].frame}, more than {MAX_TARGET_DISTANCE:g} m")

    def _set_target(self, target: pin.SE3, ee: int = 0) -> None:
        """EE ``ee``'s target pose (caller holds the lock); recorded when recording. It
        ends a way home being followed, where it is, and forgets why the last one
        stopped short (:mod:`.homing`)."""
        if self._homing.end():
            self._robots.apply_task_modes()
        self._homing.forget()
        self.inputs[ee].target = target
        self._recorder.target(ee, target)

    def set_target(self, position, wxyz, ee=0) -> None:
        """The operator's target pose of EE ``ee`` directly (world position, quaternion
        w, x, y, z). Its gizmo's later motion continues from this target."""
        ee = ee_index(self.robot, ee)
        target = pose_from(position, wxyz, "target")
        with self._lock:
            self._check_target(target, ee)
            self._set_target(target, ee)

    def move_gizmo(self, position, wxyz, ee=0) -> None:
        """EE ``ee``'s input gizmo pose. Unless the clutch is engaged, its target moves by
        ``motion_scale`` times the gizmo's displacement since its previous pose (and turns
        with the gizmo's rotation since then); the other targets stay."""
        ee = ee_index(self.robot, ee)
        gizmo = pose_from(position, wxyz, "gizmo")
        with self._lock:
            hand = self.inputs[ee]
            previous, hand.gizmo = hand.gizmo, gizmo
            if not self.clutch:
                target = followed_pose(hand.target, previous, gizmo, np.eye(3),
                                       self.motion_scale)
                try:
                    self._check_target(target, ee, "the gizmo's target")
                except ValueError:
                    hand.gizmo = previous
                    raise
                self._set_target(target, ee)

    def set_clutch(self, engaged: bool) -> None:
        """Engage (the gizmos and devices move alone) or release the clutch; on release
        every target continues from where it is, so none jumps."""
        if not isinstance(engaged, (bool, np.bool_)):
            raise ValueError(f"the clutch is engaged (True) or released (False), got {engaged!r}")
        with self._lock:
            self.clutch = bool(engaged)

    def set_motion_scale(self, scale: float) -> None:
        """Target displacement per gizmo or device displacement, in (0, 10], for every
        input; no target jumps (the mapping is incremental)."""
        scale = as_number(scale, "motion scale")
        if not 0.0 < scale <= MAX_MOTION_SCALE:
            raise ValueError(f"motion scale must be in (0, {MAX_MOTION_SCALE:g}], got {scale:g}")
        with self._lock:
            self.motion_scale = scale

    def nudge_target(self, displacement, ee=0) -> None:
        """Move EE ``ee``'s target by ``displacement`` (world, m), its gizmo staying where
        it is."""
        ee = ee_index(self.robot, ee)
        displacement = as_vector(displacement, 3, "nudge")
        if np.linalg.norm(displacement) > MAX_NUDGE:
            raise ValueError(f"a nudge moves the target by at most {MAX_NUDGE:g} m")
        with self._lock:
            target = self.inputs[ee].target.copy()
            target.translation = target.translation + displacement
            self._check_target(target, ee, "nudged target")
            self._set_target(target, ee)

    def hold_where_the_robot_is(self, ee=None) -> None:
        """Every target and gizmo (or EE ``ee``'s) on the main robot's EE pose now: what a
        browser lost mid-drag leaves behind (docs/design.md section 5.3). The robot then
        settles where it is instead of going on towards the last point of the drag,
        which may lie past a joint limit."""
        indices = range(len(self.inputs)) if ee is None else [ee_index(self.robot, ee)]
        with self._lock:
            placements = self._robots.loops["main"].ee_placements()
            for index in indices:
                self._put_hand(index, placements[index].copy())

    def gizmo_to_target(self, ee=0) -> pin.SE3:
        """Put EE ``ee``'s gizmo on its target (the UI moves its handle there); returns
        the pose."""
        ee = ee_index(self.robot, ee)
        with self._lock:
            hand = self.inputs[ee]
            hand.gizmo = hand.target.copy()
            return hand.gizmo.copy()

    def home(self, ee=None) -> str:
        """Every target and gizmo (or only EE ``ee``'s) on its home EE pose. The
        constraints stay (:meth:`.editing.ConstraintEditing.clear` removes them). Every EE with
        constraints placed: the robot goes home through them, on a joint path whose
        steps keep their rows (:mod:`.homing`, docs/design.md section 20.3); the words
        say why it cannot reach home (``""`` when it can). Every EE with no constraint
        placed: the robots back at ``q_home`` at once (a reset). A real robot (the ros2
        plant) cannot jump: its loop is reset where it is (a stop cleared, its state read
        again), then it goes home on the joint path as with constraints."""
        indices = range(len(self.inputs)) if ee is None else [ee_index(self.robot, ee)]
        if ee is None and self._ros2 is not None:
            with self._lock:
                loop = self._robots.loops["main"]
                t = loop.t
                loop.reset()  # zeros, the watchdog's stop cleared, a fresh state awaited
                loop.t, loop.q = t, self._ros2.state(loop.config.dt)
        if ee is None and (self._constraints.entries or self._ros2 is not None):
            with self._lock:
                loop = self._robots.loops["main"]
                for index in indices:  # from where the robot is: no jump when it starts
                    self._put_hand(index, loop.ee_placements()[index])
                q, frames = loop.q.copy(), list(loop.controller.constraint_frames)
                constraints = [copy.copy(constraint) for constraint in loop.constraints]
                caps = self._robots.config.max_linear_speed, self._robots.config.max_angular_speed
            # outside the lock (milliseconds to tens of them) while the robot holds its targets
            run = self._homing.plan(q, constraints, frames, caps)
            with self._lock:
                words = self._homing.follow(run, self._robots.now)
                self._robots.apply_task_modes()  # the loops in full pose while it runs
            return words
        with self._lock:
            if ee is None:
                for loop in self._robots.loops.values():
                    t = loop.t
                    loop.reset()
                    loop.t = t
            pin.framesForwardKinematics(self.robot.model, self._data, self.robot.q_home)
            for index in indices:
                self._put_hand(index,
                               self._data.oMf[self.robot.ee_frame_ids[index]].copy())
        return ""

    def _put_hand(self, ee: int, pose: pin.SE3) -> None:
        """EE ``ee``'s target and gizmo both at ``pose`` (caller holds the lock)."""
        hand = self.inputs[ee]
        self._set_target(pose, ee)
        hand.gizmo = hand.target.copy()

    def restore(self, motion_scale: float, targets: list[pin.SE3]) -> None:
        """A scene's motion scale and targets, each gizmo on its target, the clutch
        released (caller holds the lock)."""
        self.motion_scale = motion_scale
        self.clutch = False
        for ee, target in enumerate(targets):
            self._put_hand(ee, target)
