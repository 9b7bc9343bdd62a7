"""What the view draws: a consistent copy of the session under the lock, and the status
of each robot in words (:mod:`web.app.status`)."""

from __future__ import annotations

import copy
import threading

import pinocchio as pin

from constraints import Constraint
from constraints.kinematics import frame_placement
from controllers.base import velocity_joint_names
from teleop.loop import StepRecord, TeleopLoop
from teleop.robots import Robot

from ..constraint_drawing import constraint_geometry
from .collisions import CollisionScene
from .console import Console
from .editing import ConstraintEditing
from .end_effectors import ee_index
from .devices import InputDevices
from .force_control import ForceControl
from .homing import WayHome
from .plant import PlantChoice, port_readings
from .shortfall import asked_angle, explained, ports_on_chain, shortfall_words
from .recording import SessionRecording
from .robots import Robots
from .ros2_robot import Ros2Robot
from .status import Limitation, describe_limitation, not_following
from .trace import Trace


class View:
    """What the view reads of :class:`web.app.TeleopApp` (``app.view``), a component that
    owns nothing of the session but its own geometry workspace: it reads the other
    components under the session's lock.

    Parameters
    ----------
    robot : the session's robot.
    lock : the session's lock.
    robots : the robots (their loops, traces, records, settings).
    constraints : the placed constraints.
    console : the operator's console (targets, gizmos, clutch, motion scale).
    collisions : the collision avoidance and the obstacles.
    devices : the input devices.
    recorder : the session's recording (whether it records).
    force : the force control.
    homing : the way home (its words).
    plant : the session's plant choice.
    ros2 : the robot over ROS 2 (why it stopped), or None.
    """

    def __init__(self, robot: Robot, lock: threading.RLock, robots: Robots,
                 constraints: ConstraintEditing, console: Console, collisions: CollisionScene,
                 devices: InputDevices, recorder: SessionRecording, force: ForceControl,
                 homing: WayHome, plant: PlantChoice, ros2: Ros2Robot | None) -> None:
        self.robot = robot
        self._lock = lock
        self._robots = robots
        self._constraints = constraints
        self._console = console
        self._collisions = collisions
        self._devices = devices
        self._recorder = recorder
        self._force = force
        self._homing = homing
        self._plant = plant
        self._ros2 = ros2
        self.joint_names = list(velocity_joint_names(robot.model))
        self._view_data = robot.model.createData()  # for geometry queries, under the lock

    def limitation(self, which: str = "main", ee=0) -> Limitation:
        """What keeps EE ``ee`` of robot ``which`` from its target now, in words
        (:func:`web.app.status.describe_limitation`)."""
        ee = ee_index(self.robot, ee)
        with self._lock:
            loop = self._robots.loops[which]
            placement = frame_placement(self.robot.model, loop.q, self.robot.ee_frame_ids[ee],
                                        self._view_data)
            return self._limitation(which, placement, ee)

    def _limitation(self, which: str, placement: pin.SE3, ee: int) -> Limitation:
        loop = self._robots.loops[which]
        target = self._console.inputs[ee].target
        constraints = {entry.id: entry.constraint for entry in self._constraints.entries.values()}
        return self._described(loop.controller.info, self._robots.last_records.get(which), placement,
                               target, loop.refused or self._stopped(), ee, loop.task_modes[ee],
                               constraints, self._homing.words_at(self._robots.now))

    def _stopped(self) -> str:
        """Why the robot on the wire is stopped (:meth:`.ros2_robot.Ros2Robot.stopped`)."""
        return "" if self._ros2 is None else self._ros2.stopped()

    def _described(self, info, record: StepRecord | None, placement: pin.SE3,
                   target: pin.SE3, refused: str, ee: int, mode: str,
                   constraints: dict[str, Constraint], homing: str) -> Limitation:
        """What keeps EE ``ee`` at ``placement`` from ``target`` in task mode ``mode``:
        the step's words (:func:`describe_limitation`) said plainly
        (:func:`web.app.shortfall.explained`: what "Home" does, what part of the target
        is short, why, what helps)."""
        distance = self._force.motion_distance(placement, target, ee)
        limitation = describe_limitation(info, record, distance, self.joint_names, refused, ee)
        stalled = record is not None and not_following(record, ee)
        ports = ports_on_chain(self.robot.model, self.robot.ee_frame_ids[ee], constraints)
        shortfall = shortfall_words(mode, distance, asked_angle(mode, placement, target),
                                    stalled, info, self.joint_names, ports)
        return explained(limitation, shortfall, homing)

    def active_inequalities(self, which: str = "main") -> list[str]:
        """Ids of the one-sided constraints robot ``which``'s controller holds as
        equalities now (from its step's :class:`controllers.SolveInfo`)."""
        with self._lock:
            controller = self._robots.loops[which].controller
            ids = {id(e.constraint): e.id for e in self._constraints.entries.values()}
            constraints = controller.constraints
            return [ids.get(id(constraints[i]), f"#{i}") for i in controller.info.active_barriers
                    if i < len(constraints)]

    def snapshot(self, history: bool = True) -> dict:
        """A consistent copy of everything the view shows (``history``: with the plots'
        data).

        Only copies are taken under the lock (the robots' state and link placements,
        each constraint as it is now, the traces' columns); the drawings, the words and
        the plots' arrays are made from them after it, so the control thread never waits
        for them (docs/design.md section 5.3)."""
        with self._lock:
            constraints = {entry.id: copy.copy(entry.constraint)
                           for entry in self._constraints.entries.values()}
            states = {which: self._robot_state(which, loop, history)
                      for which, loop in self._robots.loops.items()}
            goals = {entry.id: (entry.kind, entry.goal.copy())
                     for entry in self._constraints.entries.values()}
            targets = [hand.target.copy() for hand in self._console.inputs]
            snapshot = {"ee_frames": self.robot.ee_frames, "targets": targets,
                        "gizmos": [hand.gizmo.copy() for hand in self._console.inputs],
                        "target": targets[0].copy(), "gizmo": self._console.gizmo.copy(),
                        "clutch": self._console.clutch, "motion_scale": self._console.motion_scale,
                        "ghost_offset": self._robots.ghost_offset.copy(),
                        "recording": self._recorder.active,
                        "config": self._robots.config, "gain": self._robots.gain,
                        "damping": self._robots.damping,
                        "plant": self._plant, "collisions": self._collisions_snapshot(),
                        "devices": self._devices.snapshot(),
                        "absolute_orientation": self._devices.absolute_orientation,
                        "force": self._force.snapshot(self._robots.loops)}
        robots = {which: self._robot_snapshot(state, constraints, targets)
                  for which, state in states.items()}
        entries = [{"id": entry_id, "kind": kind, "goal": goal,
                    **robots["main"]["constraints"][entry_id]}  # geometry, link_axis
                   for entry_id, (kind, goal) in goals.items()]
        return {"robots": robots, "constraints": entries, **snapshot}

    def _collisions_snapshot(self) -> dict:
        """The collision part of :meth:`snapshot` (caller holds the lock): the settings
        (``on``, ``self_collision``, ``safety_distance``, ``detection_distance``,
        ``approach_speed``), ``checking`` (on, with pairs to check: self-collision or an
        obstacle) and each obstacle's drawing (``id``, ``goal``, ``geometry``:
        :class:`constraints.collision.ObstacleGeometry`)."""
        settings = self._collisions.settings()
        return {**settings,
                "checking": settings["on"] and bool(settings["self_collision"] or self._collisions.obstacles),
                "obstacles": [{"id": entry.id, "kind": entry.kind, "goal": entry.goal.copy(),
                               "geometry": entry.obstacle.geometry()}
                              for entry in self._collisions.obstacles.values()]}

    def active_pairs(self, which: str = "main") -> list[str]:
        """The collision pairs robot ``which``'s controller holds at their bound now (from
        its step's :class:`controllers.SolveInfo`)."""
        with self._lock:
            return list(self._robots.loops[which].controller.info.active_pairs)

    def _robot_state(self, which: str, loop: TeleopLoop, history: bool) -> dict:
        """What :meth:`_robot_snapshot` makes robot ``which``'s part of :meth:`snapshot`
        from, copied (caller holds the lock): its state, the placements of its EEs and of
        the constrained links at its configuration, the traces' columns, the wall's force
        at each port (``ports``, :class:`web.app.plant.PortReading`; empty without a
        physics plant)."""
        model = self.robot.model
        q = loop.q.copy()
        pin.framesForwardKinematics(model, self._view_data, q)
        placements = self._view_data.oMf
        links = {entry.id: placements[model.getFrameId(entry.constraint.link)].copy()
                 for entry in self._constraints.entries.values()}
        ids = {id(entry.constraint): entry.id for entry in self._constraints.entries.values()}
        return {"spec": self._robots.specs[which], "q": q, "t": loop.t,
                "ees": [placements[frame].copy() for frame in self.robot.ee_frame_ids],
                "links": links, "record": self._robots.last_records.get(which),
                "columns": self._robots.traces[which].columns() if history else None,
                "info": loop.controller.info, "refused": loop.refused,
                "task_modes": loop.task_modes, "homing": self._homing.words_at(self._robots.now),
                "active_inequalities": self.active_inequalities(which),
                "active_pairs": self.active_pairs(which),
                # the rows its controller computed last (immutable), or None
                "collision_rows": self._collisions.rows.get(which),
                "ports": port_readings(loop, placements, ids, model),
                # what the supervisor measured and did in the last period (immutable)
                "supervision": loop.supervision}

    def _robot_snapshot(self, state: dict, constraints: dict[str, Constraint],
                        targets: list[pin.SE3]) -> dict:
        """One robot's part of :meth:`snapshot` from its copied ``state``
        (:meth:`_robot_state`), outside the lock: each constraint's drawing at its
        configuration (``constraints``: copies), what limits each EE (``targets``: every
        EE's), the plots' arrays."""
        drawings = {}
        for entry_id, placement in state.pop("links").items():
            constraint = constraints[entry_id]
            axis = self.robot.link_axes.get(constraint.link)
            drawings[entry_id] = {
                "geometry": constraint_geometry(constraint, placement), "link": constraint.link,
                "link_placement": placement,
                "link_axis": None if axis is None else placement.rotation @ axis}
        info, record, refused = state["info"], state["record"], state.pop("refused")
        modes, homing = state["task_modes"], state.pop("homing")
        limitations = [self._described(info, record, ee, target, refused, index, modes[index],
                                       constraints, homing)
                       for index, (ee, target) in enumerate(zip(state["ees"], targets))]
        columns = state.pop("columns")
        return {**state, "ee": state["ees"][0],  # every EE, the first
                "trace": None if columns is None else Trace.arrays_of(columns),
                "constraints": drawings, "limitations": limitations,
                "limitation": limitations[0]}
