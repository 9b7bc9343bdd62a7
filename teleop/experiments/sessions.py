"""Recorded operator sessions: a JSON-lines file of target poses and constraint edits.

Format (one JSON object per line, times ``t`` in seconds from the start, world frame, m):

* ``{"type": "header", "format": "cjm-teleop-session", "version": 2, "robot": "sda10f",
  "ee_frames": ["tool0"], "root_joint": "fixed", "locked_joints": {}, "q0": [...],
  "rate_hz": 1000, "kp": 20, "target_time_constant_s": 0.05}`` - first line; ``robot`` is
  a built-in name or a URDF path (then also ``ee_frame``, ``constrained_link``,
  ``link_axis``); ``locked_joints`` maps each joint frozen out of the model to the
  coordinates it is held at (``q0`` is of the model without them). Version 1 files (no
  ``ee_frames``, ``root_joint``, ``locked_joints``: the robot's defaults, nothing locked)
  are read too. An optional ``plant`` (``PlantChoice.to_dict()``: ``kind``, ``settings``,
  ``wall_stiffness_n_per_m``) is the plant a replay runs on unless told otherwise; without
  it, the kinematic plant. Version 3 adds an optional ``collisions``
  (``CollisionAvoidance.to_dict()``: ``safety_distance``, ``detection_distance``,
  ``approach_speed``, ``self_collision``, ``disabled_pairs``, ``extra_pairs`` and the
  ``obstacles``, each an obstacle's ``to_dict()``): the collision avoidance a replay runs
  with unless told otherwise; without it, none.
* ``{"type": "target", "t": 0.05, "frame": "tool0", "position": [x, y, z],
  "quaternion_wxyz": [w, x, y, z]}`` - the operator's target for the EE ``frame`` (one of
  the header's ``ee_frames``; absent: the first); it holds until the next one for that
  frame (the loop smooths it).
* ``{"type": "add", "t": 0.0, "id": "hole-1", "constraint": {"kind": "hole", ...}}`` - the
  constraint's ``to_dict()``: kinds and fields ``hole`` (link, center, link_axis, gain),
  ``plane`` and ``barrier`` (link, link_point, plane_point, normal, gain), ``point_lock``
  (link, link_point, target, gain), each with an optional ``velocity`` (moving geometry).
* ``{"type": "move", "t": 1.2, "id": "hole-1", "position": [...], "velocity": [...]}`` -
  a hole's centre, a plane's point or a lock's target moves (velocity for feed-forward).
* ``{"type": "remove", "t": 3.0, "id": "hole-1"}``
* ``{"type": "input", "t": 2.0, "source": "udp:9870", "ee": 0, "counts": {...},
  "latency_ms": {"n": 1000, "p50": 0.4, "p99": 1.1, "max": 1.6}}`` - version 4: an input
  device's counts (received, applied, dropped by reason...) and the arrival-to-command
  latency of the commands since its previous line (docs/design.md section 19.2); a
  replay reads past it.
* ``{"type": "task_modes", "t": 0.0, "modes": ["position_roll"]}`` - version 5: what the
  operator commands of each EE from then on (docs/design.md section 20; one mode per
  entry of ``ee_frames``); before the first, or without any, the full pose. A replay
  follows them.
* ``{"type": "end", "t": 10.0}`` - optional; the session's duration.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import IO, Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.collision import CollisionAvoidance
from constraints.kinematics import frame_placement
from constraints.validation import as_number, as_vector, short_repr
from teleop.json_text import parse_json
from teleop.limits import (MAX_DURATION_S, MAX_POSE_GAIN, MAX_POSITION_M, MAX_RATE_HZ,
                           MAX_SPEED_M_S, MAX_STEPS, MAX_TIME_CONSTANT_S)
from teleop.loop import target_poses
from teleop.loop.task_modes import task_mode, task_modes
from teleop.loop.moving_geometry import MAX_GEOMETRY_SPEED, advance, steer
from teleop.robots import Robot, load_robot

from .plan import Plan, home_poses
from teleop.plants.choice import PlantChoice

FORMAT = "cjm-teleop-session"
VERSION = 5
#: the versions :func:`load_session` reads (1: a single EE, no root joint or locked joints;
#: 2: no collision avoidance; 3: no input lines; 4: no task modes, the full pose)
READABLE_VERSIONS = (1, 2, 3, 4, 5)
EVENT_TYPES = ("target", "add", "move", "remove", "input", "task_modes", "end")
#: events within this of a tick's time belong to that tick (float time stamps)
TIME_EPSILON = 1e-9


class SessionError(ValueError):
    """A session file that cannot be replayed, with the line that is wrong."""


# ----------------------------------------------------------------------------- writing


class SessionRecorder:
    """Writes a session file as it happens (one flushed line per event).

    Parameters
    ----------
    path : file to write (parent directories are created).
    robot : the robot driven.
    q0 : start configuration.
    rate_hz, kp, target_time_constant_s : the loop settings, so a replay can use them.
    plant : the plant the session ran on, written in the header when given, so a replay
        runs on it too.
    collisions : the collision avoidance the session ran with (``CollisionAvoidance``, or
        its ``to_dict()``), written in the header when given, so a replay keeps it too.
    """

    def __init__(self, path: str | Path, robot: Robot, q0: np.ndarray, rate_hz: float = 1000.0,
                 kp: float = 20.0, target_time_constant_s: float = 0.0,
                 plant: PlantChoice | None = None, collisions=None) -> None:
        if collisions is not None and not isinstance(collisions, dict):
            collisions = collisions.to_dict()
        self.path = Path(path)
        if self.path.is_dir():
            raise ValueError(f"session file {str(self.path)!r} is a directory")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file: IO[str] | None = self.path.open("w", encoding="utf-8")
        except OSError as error:
            raise ValueError(f"cannot write session file {str(self.path)!r}: "
                             f"{error.strerror}") from None
        header = {"type": "header", "format": FORMAT, "version": VERSION,
                  "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                  "q0": [float(x) for x in q0], "rate_hz": rate_hz, "kp": kp,
                  "target_time_constant_s": target_time_constant_s}
        from teleop.robots import BUILTIN_ROBOTS

        if robot.name in BUILTIN_ROBOTS and robot.urdf_path.parent.name == "robots":
            header["robot"] = robot.name
        else:
            header.update(robot=str(robot.urdf_path), ee_frame=robot.ee_frame,
                          constrained_link=robot.constrained_link,
                          link_axis=[float(x) for x in robot.link_axis])
        header.update(ee_frames=list(robot.ee_frames), root_joint=robot.root_joint,
                      locked_joints={name: list(coordinates)
                                     for name, coordinates in robot.locked_joints.items()})
        if plant is not None:
            header["plant"] = plant.to_dict()
        if collisions is not None:
            header["collisions"] = CollisionAvoidance.from_dict(robot, collisions).to_dict()
        self.ee_frames = tuple(robot.ee_frames)
        self._write(header)
        self.last_t = 0.0

    def _write(self, event: dict) -> None:
        if self._file is None:
            raise ValueError(f"session {self.path} is closed")
        self._file.write(json.dumps(event) + "\n")
        self._file.flush()

    def _stamp(self, t: float) -> float:
        t = float(t)
        if not math.isfinite(t):
            raise ValueError(f"event time must be finite, got {t}")
        self.last_t = max(self.last_t, t)
        return t

    def target(self, t: float, pose: pin.SE3, frame: str | None = None) -> None:
        """The operator's target for the EE ``frame`` (default: the first, written
        without a ``frame`` field)."""
        if frame is not None and frame not in self.ee_frames:
            raise ValueError(f"unknown EE frame {frame!r}; this robot's: {list(self.ee_frames)}")
        quaternion = pin.Quaternion(pose.rotation)
        event = {"type": "target", "t": self._stamp(t)}
        if frame is not None and frame != self.ee_frames[0]:
            event["frame"] = frame
        self._write({**event, "position": [float(x) for x in pose.translation],
                     "quaternion_wxyz": [quaternion.w, quaternion.x, quaternion.y, quaternion.z]})

    def targets(self, t: float, poses: Sequence[pin.SE3]) -> None:
        """One target per EE, in ``robot.ee_frames`` order."""
        if len(poses) != len(self.ee_frames):
            raise ValueError(f"expected {len(self.ee_frames)} target poses, one per EE frame "
                             f"{list(self.ee_frames)}, got {len(poses)}")
        for frame, pose in zip(self.ee_frames, poses):
            self.target(t, pose, frame)

    def add(self, t: float, constraint_id: str, constraint: Constraint) -> None:
        self._write({"type": "add", "t": self._stamp(t), "id": str(constraint_id),
                     "constraint": constraint.to_dict()})

    def move(self, t: float, constraint_id: str, position, velocity=(0.0, 0.0, 0.0)) -> None:
        self._write({"type": "move", "t": self._stamp(t), "id": str(constraint_id),
                     "position": [float(x) for x in position],
                     "velocity": [float(x) for x in velocity]})

    def input(self, t: float, source: str, ee: int, counts: dict[str, int],
              latencies: np.ndarray) -> None:
        """An input source's counts and the latencies (s) since its previous line."""
        latency = ({"n": int(latencies.size), "p50": 1e3 * float(np.percentile(latencies, 50)),
                    "p99": 1e3 * float(np.percentile(latencies, 99)),
                    "max": 1e3 * float(latencies.max())} if latencies.size else {"n": 0})
        self._write({"type": "input", "t": self._stamp(t), "source": str(source), "ee": int(ee),
                     "counts": counts, "latency_ms": latency})

    def remove(self, t: float, constraint_id: str) -> None:
        self._write({"type": "remove", "t": self._stamp(t), "id": str(constraint_id)})

    def task_modes(self, t: float, modes: Sequence[str]) -> None:
        """What the operator commands of each EE from ``t`` on (one mode per EE)."""
        self._write({"type": "task_modes", "t": self._stamp(t),
                     "modes": list(task_modes(list(modes), len(self.ee_frames)))})

    def close(self, t: float | None = None) -> None:
        """Write the ``end`` line (at ``t``, default the last event) and close the file."""
        if self._file is None:
            return
        self._write({"type": "end", "t": self._stamp(self.last_t if t is None else t)})
        self._file.close()
        self._file = None

    def __enter__(self) -> "SessionRecorder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def record_plan(plan: Plan, path: str | Path, rate_hz: float = 1000.0,
                duration: float | None = None, plant: PlantChoice | None = None) -> Path:
    """Write a scenario's operator input as a session, one target per control tick.

    Moving geometry is recorded as ``move`` events every tick. Replaying the file at the
    same rate reproduces the scenario step for step. ``plant`` is written in the header
    (and its wall stiffness into every hole added), so a replay runs on it; the plan's
    collision avoidance (``plan.collisions``) too.
    """
    rate_hz = as_number(rate_hz, "rate_hz", positive=True, maximum=MAX_RATE_HZ)
    duration = as_number(plan.duration if duration is None else duration, "duration",
                         positive=True, maximum=MAX_DURATION_S)
    if duration * rate_hz > MAX_STEPS:
        raise ValueError(f"duration {duration:g} s at {rate_hz:g} Hz is more than {MAX_STEPS} "
                         "control periods: lower the duration or the rate")
    dt = 1.0 / rate_hz
    constraints = plan.make_constraints()
    if plant is not None:
        plant.apply_wall(constraints)
    ids = [f"{c.kind}-{i + 1}" for i, c in enumerate(constraints)]
    with SessionRecorder(path, plan.robot, plan.q0, rate_hz=rate_hz, plant=plant,
                         collisions=plan.collisions) as recorder:
        for cid, constraint in zip(ids, constraints):
            recorder.add(0.0, cid, constraint)
        before = [c.position for c in constraints]
        steps = int(round(duration * rate_hz))
        for i in range(steps + 1):  # the geometry up to the last measure, at ``duration``
            t = i * dt
            if plan.update(t, constraints, plan.q0) is not None:  # scenarios move geometry by time alone
                raise ValueError("record_plan cannot record a plan that changes its constraint set")
            for k, (cid, constraint) in enumerate(zip(ids, constraints)):
                now = constraint.position
                if not np.array_equal(now, before[k]) or constraint.velocity.any():
                    recorder.move(t, cid, now, constraint.velocity)
                    before[k] = now
            if i < steps:
                recorder.targets(t + dt, target_poses(plan.target(t + dt)))
        recorder.close(duration)
    return Path(path)


# ----------------------------------------------------------------------------- reading


@dataclass
class Session:
    """A parsed session file."""

    path: Path
    header: dict
    events: list[dict] = field(default_factory=list)

    @property
    def duration(self) -> float:
        ends = [e["t"] for e in self.events if e["type"] == "end"]
        return float(ends[-1]) if ends else max((e["t"] for e in self.events), default=0.0)


def load_session(path: str | Path) -> Session:
    """Parse and check a session file; errors (``SessionError``) name the file and line.

    Times are at most :data:`~teleop.limits.MAX_DURATION_S`; an ``add`` takes an id no
    constraint holds at that time, a ``move`` or ``remove`` one that does.
    """
    path = Path(path)
    if not path.is_file():
        raise SessionError(f"no session file at {path}")
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise SessionError(f"cannot read session file {path}: {error}") from None
    header, events = None, []
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        where = f"{path}:{number}"
        event = _parse_line(line, where)
        if header is None:
            _check_header(event, where)
            header = event
            continue
        if event["type"] not in EVENT_TYPES:
            raise SessionError(f"{where}: unknown event type {short_repr(event['type'])}")
        t = event.get("t")
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t) \
                or not 0 <= t <= MAX_DURATION_S:
            raise SessionError(f"{where}: 't' must be a time in [0, {MAX_DURATION_S:g}] s, "
                               f"got {short_repr(t)}")
        try:
            _check_event(event)
        except (ValueError, TypeError, KeyError) as error:
            raise SessionError(f"{where}: {error}") from error
        event["_line"] = number
        events.append(event)
    if header is None:
        raise SessionError(f"{path}: empty session file")
    events.sort(key=lambda e: e["t"])  # stable: equal times keep file order
    _check_ids(path, events)
    return Session(path, header, events)


def _parse_line(line: str, where: str) -> dict:
    """One line's JSON object with a ``type``, else ``SessionError``."""
    event = parse_json(line, where, SessionError)
    if not isinstance(event, dict) or "type" not in event:
        raise SessionError(f"{where}: each line must be an object with a 'type'")
    return event


#: The header's optional fields that name a frame, a link or a joint type (null: the
#: robot's default).
HEADER_TEXT_FIELDS = ("ee_frame", "constrained_link", "root_joint")


def _check_header(event: dict, where: str) -> None:
    """The first line: format, version, robot, q0 and the loop settings, each checked
    (``SessionError`` naming the field)."""
    if event["type"] != "header" or event.get("format") != FORMAT:
        raise SessionError(f"{where}: the first line must be a {FORMAT} header")
    version = event.get("version")
    if type(version) is not int or version not in READABLE_VERSIONS:  # True is not 1
        raise SessionError(f"{where}: unsupported version {short_repr(version)} "
                           f"(this program reads {list(READABLE_VERSIONS)})")
    if "robot" not in event or "q0" not in event:
        raise SessionError(f"{where}: the header needs 'robot' and 'q0'")
    try:
        if not isinstance(event["robot"], str) or not event["robot"]:
            raise ValueError(f"header 'robot' must be a built-in robot name or a URDF path, "
                             f"got {short_repr(event['robot'])}")
        q0 = event["q0"]
        if not isinstance(q0, list):
            raise ValueError(f"header 'q0' must be a list of joint coordinates, got {short_repr(q0)}")
        as_vector(q0, len(q0), "header 'q0'")
        if "rate_hz" in event:
            as_number(event["rate_hz"], "header 'rate_hz'", positive=True, maximum=MAX_RATE_HZ)
        if "kp" in event:
            as_number(event["kp"], "header 'kp'", positive=True, maximum=MAX_POSE_GAIN)
        if "target_time_constant_s" in event:
            as_number(event["target_time_constant_s"], "header 'target_time_constant_s'", 0.0,
                      maximum=MAX_TIME_CONSTANT_S)
        for name in HEADER_TEXT_FIELDS:
            if event.get(name) is not None and not isinstance(event[name], str):
                raise ValueError(f"header {name!r} must be a name, got {short_repr(event[name])}")
        frames = event.get("ee_frames")
        if frames is not None and (not isinstance(frames, list) or not frames
                                   or not all(isinstance(f, str) for f in frames)):
            raise ValueError(f"header 'ee_frames' must be a list of frame names, got {short_repr(frames)}")
        if event.get("link_axis") is not None:
            as_vector(event["link_axis"], 3, "header 'link_axis'")
        locked = event.get("locked_joints")
        if locked is not None and not isinstance(locked, dict):
            raise ValueError("header 'locked_joints' must map joint names to coordinates")
        if "plant" in event:
            PlantChoice.from_dict(event["plant"], "header 'plant'")
        if "collisions" in event:
            if version < 3:
                raise ValueError(f"header 'collisions' needs version 3 (this file says "
                                 f"{version})")
            if event["collisions"] is not None and not isinstance(event["collisions"], dict):
                raise ValueError(f"header 'collisions' must be an object or null, got "
                                 f"{short_repr(event['collisions'])}")
    except ValueError as error:
        raise SessionError(f"{where}: {error}") from None


def _check_ids(path: Path, events: list[dict]) -> None:
    """In time order, an ``add`` names an id no constraint holds, a ``move`` or ``remove``
    one that does (``SessionError`` at the line)."""
    live: dict[str, int] = {}
    for event in events:
        kind, where = event["type"], f"{path}:{event['_line']}"
        if kind == "add":
            if event["id"] in live:
                raise SessionError(f"{where}: duplicate id {event['id']!r}: the constraint "
                                   f"added at line {live[event['id']]} still holds it")
            live[event["id"]] = event["_line"]
        elif kind in ("move", "remove"):
            if event["id"] not in live:
                raise SessionError(f"{where}: no constraint with id {event['id']!r} to {kind}")
            if kind == "remove":
                del live[event["id"]]


def _check_event(event: dict) -> None:
    kind = event["type"]
    if kind == "target":
        if "frame" in event and not isinstance(event["frame"], str):
            raise ValueError(f"target 'frame' must be an EE frame name, got {event['frame']!r}")
        as_vector(event.get("position"), 3, "target 'position'", MAX_POSITION_M)
        quaternion = as_vector(event.get("quaternion_wxyz"), 4, "target 'quaternion_wxyz'")
        if abs(np.linalg.norm(quaternion) - 1.0) > 1e-6:
            raise ValueError(f"quaternion must be unit, got norm {np.linalg.norm(quaternion):.6g}")
    elif kind == "add":
        if not isinstance(event.get("id"), str):
            raise ValueError("'add' needs a string 'id'")
        Constraint.from_dict(event.get("constraint"))
    elif kind == "move":
        if not isinstance(event.get("id"), str):
            raise ValueError("'move' needs a string 'id'")
        as_vector(event.get("position"), 3, "move 'position'", MAX_POSITION_M)
        as_vector(event.get("velocity", (0.0, 0.0, 0.0)), 3, "move 'velocity'", MAX_SPEED_M_S)
    elif kind == "remove":
        if not isinstance(event.get("id"), str):
            raise ValueError("'remove' needs a string 'id'")
    elif kind == "input" and not isinstance(event.get("source"), str):
        raise ValueError("'input' needs a string 'source'")
    elif kind == "task_modes":
        modes = event.get("modes")
        if not isinstance(modes, list) or not modes:
            raise ValueError(f"'task_modes' needs a list of modes, got {short_repr(modes)}")
        for mode in modes:
            task_mode(mode)


def session_robot(session: Session) -> Robot:
    """The robot of the session's header: its EE frames, root joint and locked joints
    (held at the recorded coordinates) as recorded; a version-1 header: the defaults."""
    header = session.header
    where = f"{session.path}:1"
    locked = header.get("locked_joints") or {}
    if not isinstance(locked, dict):
        raise SessionError(f"{where}: 'locked_joints' must map joint names to coordinates")
    ee_frames = header.get("ee_frames")
    try:
        options = dict(root_joint=header.get("root_joint"), constrained_link=header.get("constrained_link"),
                       link_axis=header.get("link_axis"))
        if ee_frames is None:
            options["ee_frame"] = header.get("ee_frame")
        else:
            options["ee_frames"] = ee_frames
        if locked:
            full = load_robot(header["robot"], **options)
            configuration = full.q_home.copy()
            for name, coordinates in locked.items():
                if name not in full.model.names:
                    raise ValueError(f"locked joint {name!r} is not a joint of {header['robot']}")
                joint = full.model.joints[full.model.getJointId(name)]
                configuration[joint.idx_q:joint.idx_q + joint.nq] = as_vector(
                    coordinates, joint.nq, f"locked joint {name!r}")
            options.update(locked_joints=list(locked), locked_configuration=configuration)
        return load_robot(header["robot"], **options)
    except ValueError as error:
        raise SessionError(f"{where}: {error}") from error


#: How far (m) the geometry of a session's ``add`` event may be off its link when added.
ADD_TOLERANCE = 1e-3


def _placed(constraint: Constraint, robot: Robot, q: np.ndarray, where: str) -> Constraint:
    """``constraint`` if its geometry is on its link at ``q``, else ``SessionError``."""
    try:
        placement = frame_placement(robot.model, q, constraint.link)
    except ValueError as error:
        raise SessionError(f"{where}: {error}") from error
    off = constraint.violation(placement)
    if off > ADD_TOLERANCE:
        raise SessionError(f"{where}: the {constraint.kind} is {off:.3g} m off link "
                           f"{constraint.link!r} when it is added (tolerance {ADD_TOLERANCE:g} m)")
    return constraint


def session_plant(session: Session) -> PlantChoice:
    """The plant of the session's header (the kinematic one when it names none)."""
    if "plant" not in session.header:
        return PlantChoice()
    return PlantChoice.from_dict(session.header["plant"], "header 'plant'")


def session_collisions(session: Session, robot: Robot) -> dict | None:
    """The collision avoidance of the session's header on ``robot`` (its ``to_dict()``),
    None when it has none; ``SessionError`` at the header's line naming the field."""
    collisions = session.header.get("collisions")
    if collisions is None:
        return None
    try:
        return CollisionAvoidance.from_dict(robot, collisions).to_dict()
    except ValueError as error:
        raise SessionError(f"{session.path}:1: header 'collisions': {error}") from None


def session_plan(session: Session, robot: Robot | None = None) -> Plan:
    """A :class:`Plan` that replays the session: zero-order hold of the targets, and the
    constraint edits applied at their times (each run starts from no constraint); the
    header's collision avoidance, if any."""
    robot = robot or session_robot(session)
    collisions = session_collisions(session, robot)
    q0 = np.asarray(session.header["q0"], dtype=float)
    if q0.shape != (robot.model.nq,):
        raise SessionError(f"{session.path}:1: header 'q0' has {q0.size} values, the robot "
                           f"has nq = {robot.model.nq}")
    starts = home_poses(robot, q0)
    held: dict[str, tuple[np.ndarray, list[pin.SE3]]] = {}  # per EE frame: times, poses
    for frame in robot.ee_frames:
        events = [e for e in session.events
                  if e["type"] == "target" and e.get("frame", robot.ee_frame) == frame]
        held[frame] = (np.array([e["t"] for e in events]),
                       [pin.SE3(pin.Quaternion(*e["quaternion_wxyz"]).normalized().matrix(),
                                np.asarray(e["position"], dtype=float)) for e in events])
    for event in session.events:
        if event["type"] == "target" and event.get("frame", robot.ee_frame) not in held:
            raise SessionError(f"{session.path}:{event['_line']}: unknown EE frame "
                               f"{event['frame']!r}; the robot's: {list(robot.ee_frames)}")
    edits = [e for e in session.events if e["type"] in ("add", "move", "remove")]
    mode_events = [e for e in session.events if e["type"] == "task_modes"]
    for event in mode_events:
        if len(event["modes"]) != len(robot.ee_frames):
            raise SessionError(f"{session.path}:{event['_line']}: {len(event['modes'])} task "
                               f"modes for {len(robot.ee_frames)} end effectors")
    mode_times = np.array([e["t"] for e in mode_events])
    state: dict = {}

    def modes_at(t: float) -> tuple[str, ...] | None:
        index = int(np.searchsorted(mode_times, t + TIME_EPSILON, side="right")) - 1
        return None if index < 0 else tuple(mode_events[index]["modes"])

    def make_constraints() -> list[Constraint]:
        state.update(cursor=0, by_id={}, goals={}, t=None,
                     dt=1.0 / float(session.header.get("rate_hz", 1000.0)))
        return []

    def target(t: float) -> list[pin.SE3]:
        poses = []
        for start, (times, recorded) in zip(starts, held.values()):
            index = int(np.searchsorted(times, t + TIME_EPSILON, side="right")) - 1
            poses.append(start if index < 0 else recorded[index])
        return poses

    def update(t: float, constraints: list[Constraint], q: np.ndarray) -> list[Constraint] | None:
        changed = False
        by_id, goals = state["by_id"], state["goals"]
        elapsed = 0.0 if state["t"] is None else t - state["t"]
        state["t"] = t
        if elapsed > 0.0:
            state["dt"] = elapsed
        dt = state["dt"]
        for constraint in by_id.values():  # the motion of the period that ended
            advance(constraint, elapsed)
        snapped = set()
        while state["cursor"] < len(edits) and edits[state["cursor"]]["t"] <= t + TIME_EPSILON:
            event = edits[state["cursor"]]
            state["cursor"] += 1
            where = f"{session.path}:{event['_line']}"
            cid = event["id"]
            if event["type"] == "add":
                by_id[cid] = _placed(Constraint.from_dict(event["constraint"]), robot, q, where)
                changed = True
            elif cid not in by_id:
                raise SessionError(f"{where}: no constraint with id {cid!r} to {event['type']}")
            elif event["type"] == "remove":
                del by_id[cid]
                goals.pop(cid, None)
                changed = True
            else:  # a recorded motion: its position at event time, moving at its velocity
                position = np.asarray(event["position"], dtype=float)
                velocity = np.asarray(event.get("velocity", (0.0, 0.0, 0.0)), dtype=float)
                goals[cid] = (position, velocity, float(event["t"]))
                if np.linalg.norm(position - by_id[cid].position) <= MAX_GEOMETRY_SPEED * dt:
                    by_id[cid].move_to(position, velocity)  # on the recorded path already
                    snapped.add(cid)
        for cid, (position, velocity, since) in goals.items():  # else glide, speed-capped
            if cid not in snapped:
                steer(by_id[cid], position + velocity * (t + dt - since), dt)
        return list(by_id.values()) if changed else None

    return Plan(name=session.path.stem, robot=robot, q0=q0, duration=session.duration,
                make_constraints=make_constraints, target=target, update=update,
                description=f"recorded session {session.path.name}", collisions=collisions,
                task_modes=modes_at)
