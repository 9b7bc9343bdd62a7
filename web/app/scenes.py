"""Scenes: the whole state of a session (robots' configurations, constraints, targets,
controllers, settings, collision avoidance and obstacles) saved to and loaded from the scene folder (format in
:mod:`web.scene`): :class:`Scenes`, the component ``app.scenes`` of
:class:`web.app.TeleopApp`."""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

import numpy as np
import pinocchio as pin

from constraints.kinematics import frame_placement
from controllers.base import velocity_joint_names
from teleop.robots import Robot

from .robots import Robots
from ..folders import Folder
from ..scene import FORMAT as SCENE_FORMAT
from ..scene import VERSION as SCENE_VERSION
from ..scene import (
    Scene,
    parse_scene,
    read_scene_file,
    robot_source,
    robot_to_dict,
    same_robot,
    write_scene_file,
)
from .collisions import CollisionScene, ObstacleEntry
from .console import Console, pose_from
from .editing import ConstraintEditing, ConstraintEntry
from .limits import (
    MAX_DAMPING,
    MAX_GHOST_OFFSET,
    MAX_MOTION_SCALE,
    MAX_TARGET_DISTANCE,
    ROS2_SCENE_TOLERANCE,
    checked_rate,
)
from .force_control import ForceControl
from .plant import PlantChoice, apply_wall
from .ros2_robot import Ros2Robot


def pose_to_dict(pose: pin.SE3) -> dict:
    """``{"position": [x, y, z], "wxyz": [w, x, y, z]}`` (a scene's target)."""
    quaternion = pin.Quaternion(pose.rotation)
    return {"position": [float(x) for x in pose.translation],
            "wxyz": [quaternion.w, quaternion.x, quaternion.y, quaternion.z]}


class Scenes:
    """Saving and loading the scene of :class:`web.app.TeleopApp` (``app.scenes``): reads
    every component a scene holds and, applying one, restores each of them (all or
    nothing); the scene files are those of :attr:`folder`."""

    def __init__(self, robot: Robot, lock: threading.RLock, plant: PlantChoice,
                 ros2: Ros2Robot | None, folder: Folder, robots: Robots, console: Console,
                 constraints: ConstraintEditing, collisions: CollisionScene,
                 force: ForceControl, restart_history: Callable[[float], None]) -> None:
        self.robot = robot
        self.folder = folder  # the scene folder: scenes are read and written there only
        self.joint_names = list(velocity_joint_names(robot.model))
        self._lock = lock
        self._plant = plant
        self._ros2 = ros2
        self._robots = robots
        self._console = console
        self._constraints = constraints
        self._collisions = collisions
        self._force = force
        self._restart_history = restart_history  # the history's next sample at a time (s)

    def scene(self) -> dict:
        """The scene as a JSON-ready dict (format in :mod:`web.scene`)."""
        with self._lock:
            targets = [pose_to_dict(hand.target) for hand in self._console.inputs]
            several = {} if len(targets) == 1 else {"targets": [
                {"frame": hand.frame, **pose} for hand, pose in zip(self._console.inputs, targets)]}
            settings = self._collisions.avoidance.to_dict()
            del settings["obstacles"]  # with their ids and goals, below
            return {
                "format": SCENE_FORMAT, "version": SCENE_VERSION,
                "created": datetime.now().isoformat(timespec="seconds"),
                "robot": robot_to_dict(self.robot),
                "controllers": {"main": self._robots.specs["main"], "ghost": self._robots.specs.get("ghost")},
                "gain": self._robots.gain, "damping": self._robots.damping,
                "rate": self._robots.config.rate,
                "orientation_weight": self._robots.orientation_weight,
                "task_mode": self._robots.task_mode,
                "motion_scale": self._console.motion_scale,
                "ghost_offset": [float(x) for x in self._robots.ghost_offset],
                "q": {which: [float(x) for x in loop.q] for which, loop in self._robots.loops.items()},
                "target": targets[0], **several,
                "constraints": [{"id": e.id, "goal": [float(x) for x in e.goal],
                                 "constraint": e.constraint.to_dict()}
                                for e in self._constraints.entries.values()],
                "collisions": {"on": self._collisions.on, **settings},
                "obstacles": [{"id": e.id, "goal": [float(x) for x in e.goal],
                               "obstacle": e.obstacle.to_dict()}
                              for e in self._collisions.obstacles.values()],
                "force": self._force.setup(),
            }

    def save(self, name: str | None = None) -> Path:
        """Write the scene as file ``name`` of the scene folder (default: a new name);
        its path. A name that is not a plain file name of that folder is refused
        (:class:`web.folders.Folder`)."""
        if name is None or isinstance(name, str) and not name.strip():
            name = self.folder.unused_name(f"scene-{datetime.now():%Y%m%d-%H%M%S}")
        return write_scene_file(self.folder.writable(name), self.scene())

    def load(self, name: str) -> None:
        """Read file ``name`` of the scene folder and apply it (:meth:`apply`)."""
        self.apply(read_scene_file(self.folder.existing(name)))

    def apply(self, data: dict) -> None:
        """Put the app in the state a scene describes: robots' configurations, constraints,
        target, controllers, gain, damping, rate, motion scale, ghost offset, collision
        avoidance and obstacles (a version 1 scene: no obstacles, the session's collision
        settings), the force control's tissue and settings (version 3; force control
        itself stays as it is, off without a tissue). All or nothing: a scene that cannot
        be applied raises ``ValueError`` and changes nothing. The scene must be for this
        robot (another robot needs ``teleop web --scene``)."""
        scene = parse_scene(data, self.robot.model.nq, self.robot.ee_frames)
        if not same_robot(self.robot, scene.robot):
            raise ValueError(f"this scene is for robot {scene.robot.get('source')!r}, this UI "
                             f"runs {robot_source(self.robot)!r}: start "
                             "`teleop web --scene FILE` to open it with its robot")
        self._check_scene(scene)
        if self._ros2 is not None:
            self._ros2.refuse_ghost(scene.ghost)
            scene = self._scene_where_the_robot_is(scene)
        if scene.force is not None:
            self._force.check_tissue()
        constraints = [placed.constraint for placed in scene.constraints]
        for constraint in constraints:
            constraint.gain = scene.gain
            apply_wall(constraint, self._plant.wall_stiffness)
        config = dataclasses.replace(self._robots.config, rate=scene.rate)
        avoidance, collisions_on = self._collisions.for_scene(
            scene.collisions, [placed.obstacle for placed in scene.obstacles], constraints,
            config.dt)
        with self._lock:
            t = self._robots.now
            specs = {"main": scene.main, **({"ghost": scene.ghost} if scene.ghost else {})}
            loops = {}
            force = self._force
            previous = None
            if not scene.keep_force:  # the loops' plants and laws take the scene's
                setup = scene.force
                previous = force.take_setup(None if setup is None else setup.tissue,
                                            force.setpoint if setup is None else setup.setpoint,
                                            force.axes if setup is None else setup.axes)
            try:
                for which, spec in specs.items():  # raises ValueError: nothing changed yet
                    loop = self._robots.make_loop(spec, q=scene.q[which], constraints=constraints,
                                           config=config,
                                           orientation_weight=scene.orientation_weight,
                                           task_mode=scene.task_mode,
                                           damping=scene.damping,
                                           avoidance=avoidance, collisions_on=collisions_on)
                    loop.t = t
                    loops[which] = loop
            except BaseException:  # all or nothing: the force settings back too
                if previous is not None:
                    force.restore_setup(previous)
                raise
            if previous is not None:
                force.history.clear()  # the plot starts with the scene's tissue
            self._robots.restore(loops, specs, config, scene.gain, scene.damping,
                                scene.orientation_weight, scene.task_mode)
            self._constraints.restore({placed.id: ConstraintEntry(
                placed.id, placed.goal.copy(), constraint=placed.constraint).restored()
                for placed in scene.constraints})
            self._collisions.restore(avoidance, collisions_on, {placed.id: ObstacleEntry(
                placed.id, placed.goal.copy(), obstacle=placed.obstacle).restored()
                for placed in scene.obstacles})
            self._robots.set_ghost_offset(scene.ghost_offset.copy())
            self._console.restore(scene.motion_scale, [pose_from(position, wxyz, "target")
                                                      for position, wxyz in scene.targets])
            self._restart_history(t)

    def _scene_where_the_robot_is(self, scene: Scene) -> Scene:
        """A scene for the real robot (the ros2 plant), which cannot jump: refused unless
        the robot is at the scene's configuration (within :data:`ROS2_SCENE_TOLERANCE` on
        every joint: its constraints were placed there), then taken from where the robot
        is, every target on its end effector (opening a scene never moves the robot)."""
        with self._lock:
            q = self._robots.loops["main"].q.copy()
        gap = np.abs(scene.q["main"] - q)
        if float(gap.max()) > ROS2_SCENE_TOLERANCE:
            joint = self.joint_names[int(np.argmax(gap))]
            raise ValueError(
                f"this scene puts the robot {float(gap.max()):.3g} rad from where the ROS 2 "
                f"robot is (joint {joint}; at most {ROS2_SCENE_TOLERANCE:g} rad): a real "
                "robot cannot jump there, move it to the scene's configuration first")
        poses = [frame_placement(self.robot.model, q, frame) for frame in self.robot.ee_frame_ids]
        targets = tuple((pose.translation.copy(), np.array(pose_to_dict(pose)["wxyz"]))
                        for pose in poses)
        return dataclasses.replace(scene, q={"main": q}, targets=targets,
                                   target_position=targets[0][0], target_wxyz=targets[0][1])

    def _check_scene(self, scene: Scene) -> None:
        """``ValueError`` for a parsed scene this app cannot take: a configuration outside
        the joint limits, a setting out of its bounds, a target out of reach."""
        model = self.robot.model
        for which, q in scene.q.items():
            outside = np.flatnonzero((q < model.lowerPositionLimit - 1e-9)
                                     | (q > model.upperPositionLimit + 1e-9))
            if outside.size:
                raise ValueError(f"scene q.{which} is outside the joint limits of "
                                 f"{[self.joint_names[i] for i in outside]}")
        checked_rate(scene.rate, "scene rate")
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
