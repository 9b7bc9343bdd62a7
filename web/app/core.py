"""The browser session's core, without any browser: :class:`TeleopApp`.

Everything the UI does goes through :class:`TeleopApp`, so it can be tested without
viser: a small front over components that own their state, each given the session's one
lock and the collaborators it reads at construction, and each taking the lock in its
actions (which raise ``ValueError`` with a message meant for the operator; the UI shows it
as a notification): ``app.robots`` (:mod:`.robots`: the loops, their controllers and
settings), ``app.constraints`` (:mod:`.editing`, from the registry's declarations,
:mod:`.placing`), ``app.console`` (:mod:`.console`: targets, gizmos, clutch, motion
scale, home), ``app.collisions`` (:mod:`.collisions`: the avoidance and the obstacles),
``app.devices`` (:mod:`.devices`), ``app.force`` (:mod:`.force_control`), ``app.homing``
(:mod:`.homing`), ``app.recorder`` (:mod:`.recording`), ``app.view`` (:mod:`.view`:
what the view reads), ``app.scenes`` (:mod:`.scenes`: saving, loading and applying a
scene) and ``app.ticker`` (:mod:`.tick`: the control tick). The front keeps the tick's
call (:meth:`TeleopApp.step`), the session's time and starting and stopping a recording.

Threading (docs/design.md section 5.3): :class:`web.app.ControlThread` calls
:meth:`TeleopApp.step` at the control rate and never touches viser; the view thread reads
:meth:`web.app.view.View.snapshot` (``app.view``).
"""

from __future__ import annotations

from functools import partial
import threading
from pathlib import Path


from controllers.base import velocity_joint_names
from teleop.loop import LoopConfig
from teleop.options import JERK_LIMIT
from teleop.plants import PlantSettings
from teleop.plants.ros2.settings import Ros2Settings
from teleop.robots import Robot

from ..folders import Folder
from .collisions import CollisionScene, CollisionSession
from .console import Console
from .devices import InputDevices
from .editing import ConstraintEditing, EditingSession
from .force_control import ForceControl
from .homing import WayHome
from .limits import DEFAULT_SMOOTHING, MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED, checked_rate
from .plant import PlantChoice, session_plant
from .recording import SessionRecording
from .robots import Robots
from .ros2_robot import Ros2Robot
from .scenes import Scenes
from .tick import Ticker
from .view import View


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
    plant : what every loop runs on, ``"kinematic"`` (the ideal integrator) or
        ``"mujoco"`` (a :class:`teleop.plants.MujocoPlant` per loop, docs/design.md
        section 17); ``plant_settings`` its body and servos (payload...).
        ``"ros2"``: the main loop drives one robot over ROS 2 (:mod:`.ros2_robot`,
        docs/ros2.md), ``ros2_settings`` its topics and domain; no ghost.
    wall_stiffness : the abdominal wall's stiffness (N/m) at every port of the session;
        None: each port's own.
    collisions : whether the controllers keep the robot's link pairs and the obstacles
        apart (docs/design.md section 18; :mod:`.collisions`); ``collision_settings``
        the avoidance's ``self_collision`` (default: on for a robot with several arms),
        ``safety_distance``, ``detection_distance``, ``approach_speed``; its damper counts
        on the plant's response time (``PlantChoice.response_time``, as ``teleop
        compare`` does: docs/design.md 18.6).
    acceleration_limits : whether the controllers keep the robot's joint acceleration
        limits (docs/design.md section 8.4; on by default).
    jerk_limit : a jerk limit (rad/s^3) every controller keeps on every joint
        (docs/design.md section 8.5), or None; it needs the acceleration limits.
    """

    def __init__(self, robot: Robot, controller: str = "cjm", ghost: str | None = None,
                 rate: float = 1000.0, kp: float = 20.0, record_dir: str | Path = "sessions",
                 scene_dir: str | Path = "scenes", plant: str = "kinematic",
                 plant_settings: PlantSettings | None = None,
                 wall_stiffness: float | None = None, collisions: bool = True,
                 collision_settings: dict | None = None,
                 acceleration_limits: bool = True, jerk_limit: float | None = None,
                 ros2_settings: Ros2Settings | None = None) -> None:
        rate = checked_rate(rate)
        if jerk_limit is not None and not acceleration_limits:
            raise ValueError("a jerk limit needs the acceleration limits (docs/design.md 8.5)")
        self.plant = PlantChoice(plant, plant_settings or PlantSettings(), wall_stiffness,
                                 (ros2_settings or Ros2Settings()) if plant == "ros2" else None)
        self.ros2 = Ros2Robot(robot, self.plant) if plant == "ros2" else None
        if self.ros2 is not None:
            self.ros2.refuse_ghost(ghost)
        self.robot = robot
        self._lock = threading.RLock()
        self.joint_names = list(velocity_joint_names(robot.model))
        config = LoopConfig(rate=rate, kp=kp, target_time_constant=DEFAULT_SMOOTHING,
                            max_linear_speed=MAX_LINEAR_SPEED, max_angular_speed=MAX_ANGULAR_SPEED)
        self.homing = WayHome(robot)  # the way home followed now (:mod:`.homing`)
        self.recordings = Folder(record_dir, "recording", ".jsonl")
        scenes = Folder(scene_dir, "scene", ".json")
        self.record_dir, self.scene_dir = self.recordings.root, scenes.root
        self.recorder = SessionRecording(self.recordings, lambda: self.now, robot.ee_frames)
        self.constraints = ConstraintEditing(robot, self._lock, self.plant.wall_stiffness,
                                             self.recorder, EditingSession(
            configuration=lambda: self.robots.loops["main"].q, gain=lambda: self.robots.gain,
            changed=lambda: self.robots.sync_constraints()))
        self.collisions = CollisionScene(
            robot, config.dt, collisions, dict(collision_settings or {}), self._lock,
            CollisionSession(
                controllers=lambda: [loop.controller for loop in self.robots.loops.values()],
                constraints=self.constraints.placed, tips=lambda: self.robots.loops["main"].ee_placements(),
                period=lambda: self.robots.config.dt), self.plant.response_time)
        # before the first loop: it makes their plants
        self.force = ForceControl(robot, self.plant, self._lock, lambda: self.robots.loops,
                                  partial(session_plant, self.plant, robot, self.ros2),
                                  lambda: self.robots.rebuild(dict(self.robots.specs)))
        self.robots = Robots(robot, self._lock, config, controller,
                             None if self.ros2 is None else self.ros2.state(config.dt),
                             self.constraints.placed, self.collisions, self.force, self.homing,
                             self.recorder, self.ros2, acceleration_limits,
                             None if jerk_limit is None else JERK_LIMIT.check(jerk_limit))
        if ghost:
            self.robots.set_ghost(ghost)
        self.console = Console(robot, self._lock, self.robots, self.constraints, self.homing,
                               self.recorder, self.ros2)
        self.devices = InputDevices(self.recorder, self._lock, len(robot.ee_frames))
        self.view = View(robot, self._lock, self.robots, self.constraints, self.console,
                         self.collisions, self.devices, self.recorder, self.force, self.homing,
                         self.plant, self.ros2)
        self.ticker = Ticker(self._lock, self.robots, self.console, self.constraints,
                             self.collisions, self.devices, self.homing, self.recorder, self.force)
        self.scenes = Scenes(robot, self._lock, self.plant, self.ros2, scenes, self.robots,
                             self.console, self.constraints, self.collisions, self.force,
                             self.ticker.restart_history)

    @property
    def now(self) -> float:
        """The app's time (s): the main robot's loop time."""
        return self.robots.now

    def step(self) -> float:
        """One control period for every robot (called by the control thread); the time the
        controllers took (us) (:meth:`.tick.Ticker.step`)."""
        return self.ticker.step()

    @property
    def advance_us(self) -> float:
        """The loops' hot path in the last tick (us) (:attr:`.tick.Ticker.advance_us`)."""
        return self.ticker.advance_us

    def start_recording(self, name: str | None = None) -> Path:
        """Record the session to file ``name`` of the recording folder (default: a new
        name, by date); its path (:class:`.recording.SessionRecording`). A name already in
        the folder is refused: a recording never replaces another."""
        with self._lock:
            return self.recorder.start(
                name, self.robot, self.robots.loops["main"].q, self.robots.config,
                [(entry.id, entry.constraint) for entry in self.constraints.entries.values()],
                self.robots.loops["main"].task_modes, [hand.target for hand in self.console.inputs])

    def stop_recording(self) -> Path:
        """Close the recording; its path."""
        with self._lock:
            return self.recorder.stop()
