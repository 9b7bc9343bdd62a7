"""Scenes: what an operator set up in the browser, as one JSON file.

A scene holds the robot (a built-in name or a URDF path with its options), the placed
constraints (each its ``Constraint.to_dict()``, with its id and where its gizmo was put),
the robots' configurations, the target, the controller specs, the drift gain, the damping,
the control rate, the motion scale and the ghost's offset::

    {"format": "cjm-teleop-scene", "version": 2,
     "robot": {"source": "sda10f", "ee_frame": "tool0", "constrained_link": "arm_link_5_r",
               "link_axis": [0, 0, -1], "package_dirs": null, "q_home": [...]},
     "controllers": {"main": "cjm", "ghost": "qp:daqp"},
     "gain": 100.0, "damping": 0.0, "rate": 1000.0, "motion_scale": 1.0,
     "orientation_weight": 1.0, "task_mode": "auto",
     "ghost_offset": [0.0, 0.9, 0.0],
     "q": {"main": [...], "ghost": [...]},
     "target": {"position": [x, y, z], "wxyz": [w, x, y, z]},
     "constraints": [{"id": "<kind>-1", "goal": [x, y, z], "constraint": {"kind": "<kind>", ...}}],
     "collisions": {"on": true, "self_collision": false, "safety_distance": 0.005,
                    "detection_distance": 0.05, "approach_speed": 0.5,
                    "disabled_pairs": [], "extra_pairs": []},
     "obstacles": [{"id": "sphere-1", "goal": [x, y, z],
                    "obstacle": {"kind": "sphere", "center": [x, y, z], "radius": 0.04}}]}

Version 2 added ``"collisions"`` (whether the controllers keep the pairs apart, and the
:class:`constraints.collision.CollisionAvoidance` settings, docs/design.md section 18) and
``"obstacles"`` (each its ``Obstacle.to_dict()`` with its id and where its gizmo was put).
A version 1 scene still loads: it has no obstacles and keeps the session's collision
settings. A session on the physics plant or a robot over ROS 2 also writes the damper's
``"response_time"`` (``tau``, s: its servos' time constant, docs/design.md 18.6; over ROS 2
``--response-time``, docs/ros2.md); a scene opened takes the opening session's (its
plant's, 0 on the kinematic one), whatever it says.

Version 3 added ``"force"``: the page's force control (docs/design.md section 21.6), the
tissue placed under the tool and the force law's settings, or null when no tissue is
placed::

     "force": {"tissue": {"point": [x, y, z], "normal": [x, y, z], "stiffness": 250.0,
                          "damping": 0.5},
               "setpoint": [0.0, 0.0, 1.0], "axes": [false, false, true]}

Loading it places the tissue and takes the settings; force control itself stays as the
page has it (off unless the operator turned it on), so opening a scene never starts a
force law on its own. A version 1 or 2 scene keeps the page's force control as it is.

A robot with several end effectors (docs/design.md section 11) adds ``"targets"``, one
``{"frame", "position", "wxyz"}`` per entry of ``robot.ee_frames`` in that order
(``"target"`` is the first), and its robot entry names them all: ``"ee_frames"``,
``"constrained_links"`` (each link with its axis), and, when they are not the defaults,
``"root_joint"`` (``"planar"``: a mobile base) and ``"locked_joints"`` (each with the
coordinates it is held at). A single-EE scene has none of these keys.

:func:`parse_scene` checks a scene and turns it into a :class:`Scene`; anything wrong raises
``ValueError`` naming the field (the UI shows it as a notification, the CLI as one line).
Applying a scene to a running app is :meth:`web.app.scenes.Scenes.apply` (``app.scenes``).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from constraints import Constraint
from constraints.collision import Obstacle
from constraints.validation import as_number, as_vector, short_repr
from teleop.files import replace_file
from teleop.json_text import parse_json
from teleop.limits import MAX_DAMPING, MAX_FORCE_SETPOINT_N, MAX_RATE_HZ
from teleop.loop.task_modes import AUTO, task_mode
from teleop.plants.tissue import TissueSurface
from teleop.robots import BUILTIN_ROBOTS, Robot, load_robot

FORMAT = "cjm-teleop-scene"
VERSION = 3
#: the versions this program reads
VERSIONS = (1, 2, 3)


def robot_source(robot: Robot) -> str:
    """A built-in robot's name, else the path of its URDF."""
    if robot.name in BUILTIN_ROBOTS and robot.urdf_path.parent.name == "robots":
        return robot.name
    return str(robot.urdf_path)


def robot_to_dict(robot: Robot) -> dict:
    """Everything :func:`load_robot` needs to load ``robot`` again."""
    source = robot_source(robot)
    builtin = source in BUILTIN_ROBOTS
    description = {"source": source, "ee_frame": robot.ee_frame,
                   "constrained_link": robot.constrained_link,
                   "link_axis": [float(x) for x in robot.link_axis],
                   "package_dirs": None if builtin else list(robot.package_dirs),
                   "q_home": [float(x) for x in robot.q_home]}
    if len(robot.ee_frames) > 1 or len(robot.constrained_links) > 1:
        description["ee_frames"] = list(robot.ee_frames)
        description["constrained_links"] = {link: [float(x) for x in axis]
                                            for link, axis in robot.link_axes.items()}
    if robot.root_joint != "fixed":
        description["root_joint"] = robot.root_joint
    if robot.locked_joints:
        description["locked_joints"] = {name: list(values)
                                        for name, values in robot.locked_joints.items()}
    return description


def _full_configuration(source: str, data: Mapping, locked: Mapping) -> list[float]:
    """The URDF's configuration (locked joints included) of a scene's robot whose
    ``q_home`` has the kept joints only: what ``load_robot(q_home=...)`` takes."""
    model = load_robot(source, root_joint=data.get("root_joint"),
                       package_dirs=data.get("package_dirs")).model
    kept = iter(as_vector(data.get("q_home"), model.nq - sum(
        model.nqs[model.getJointId(name)] for name in locked), "scene robot.q_home"))
    q = []
    for joint in range(1, model.njoints):
        name = model.names[joint]
        if name in locked:
            values = as_vector(locked[name], model.nqs[joint], f"scene robot.locked_joints.{name}")
            q += [float(x) for x in values]
        else:
            q += [float(next(kept)) for _ in range(model.nqs[joint])]
    return q


#: The scene robot's fields that hold a name (null: the robot's default).
ROBOT_NAME_FIELDS = ("ee_frame", "constrained_link", "root_joint")


def check_robot_fields(data: Any) -> Mapping:
    """A scene's ``robot`` object, its fields of the right kinds (``ValueError`` naming
    the field); whether the robot has those frames and links is :func:`load_robot`'s to say."""
    if not isinstance(data, Mapping) or not isinstance(data.get("source"), str) \
            or not data["source"]:
        raise ValueError("scene 'robot' must be an object with a 'source' (a built-in robot "
                         "name or a URDF path)")
    for name in ROBOT_NAME_FIELDS:
        if data.get(name) is not None and not isinstance(data[name], str):
            raise ValueError(f"scene robot.{name} must be a name, got {short_repr(data[name])}")
    for name in ("ee_frames", "package_dirs"):
        value = data.get(name)
        if value is not None and (not isinstance(value, list)
                                  or not all(isinstance(item, str) for item in value)):
            raise ValueError(f"scene robot.{name} must be a list of names, got {short_repr(value)}")
    if data.get("link_axis") is not None:
        as_vector(data["link_axis"], 3, "scene robot.link_axis")
    q_home = data.get("q_home")
    if q_home is not None:
        if not isinstance(q_home, list):
            raise ValueError(f"scene robot.q_home must be a list of numbers, got {short_repr(q_home)}")
        as_vector(q_home, len(q_home), "scene robot.q_home")
    links = data.get("constrained_links")
    if links is not None:
        if not isinstance(links, Mapping):
            raise ValueError("scene robot.constrained_links must map each link to its axis")
        for link, axis in links.items():
            as_vector(axis, 3, f"scene robot.constrained_links.{link}")
    locked = data.get("locked_joints")
    if locked is not None and not isinstance(locked, Mapping):
        raise ValueError("scene robot.locked_joints must map each locked joint to its coordinates")
    return data


def robot_from_dict(data: Any) -> Robot:
    """Load the robot a scene names (``ValueError`` if it cannot be; a missing URDF is
    also a ``FileNotFoundError``)."""
    data = check_robot_fields(data)
    source = data["source"]
    links = data.get("constrained_links")
    if links is not None and not isinstance(links, Mapping):
        raise ValueError("scene robot.constrained_links must map each link to its axis")
    several_links = links is not None and len(links) > 1  # only a built-in robot's own
    frames = {"ee_frames": data["ee_frames"]} if data.get("ee_frames") else \
        {"ee_frame": data.get("ee_frame")}
    locked = data.get("locked_joints") or {}
    if not isinstance(locked, Mapping):
        raise ValueError("scene robot.locked_joints must map each locked joint to its coordinates")
    q_home = _full_configuration(source, data, locked) if locked else data.get("q_home")
    robot = load_robot(source, **frames,
                       constrained_link=None if several_links else data.get("constrained_link"),
                       link_axis=None if several_links else data.get("link_axis"),
                       package_dirs=data.get("package_dirs"), q_home=q_home,
                       locked_joints=list(locked) or None, root_joint=data.get("root_joint"))
    if not same_robot(robot, data):
        raise ValueError(f"scene robot: {source!r} does not have the constrained links "
                         f"{dict(links or {})}; it has "
                         f"{dict(robot_to_dict(robot).get('constrained_links', {}))}")
    return robot


def same_robot(robot: Robot, data: Mapping) -> bool:
    """Whether the scene's robot description is ``robot`` (same source, frames, links,
    axes, root joint and locked joints)."""
    mine = robot_to_dict(robot)
    if data.get("source") != mine["source"]:
        return False
    for key in ("ee_frame", "constrained_link", "ee_frames", "root_joint"):
        if data.get(key, mine.get(key)) != mine.get(key):
            return False
    if set(data.get("locked_joints") or {}) != set(mine.get("locked_joints", {})):
        return False
    axis = data.get("link_axis")
    if axis is not None and not np.allclose(np.asarray(axis, dtype=float), robot.link_axis):
        return False
    links = data.get("constrained_links")
    if links is None:
        return True
    return list(links) == list(robot.link_axes) and all(
        np.allclose(np.asarray(links[link], dtype=float), robot.link_axes[link]) for link in links)


@dataclass(frozen=True)
class PlacedConstraint:
    """One constraint of a scene: its id, the constraint, where its gizmo was put."""

    id: str
    constraint: Constraint
    goal: np.ndarray


@dataclass(frozen=True)
class PlacedObstacle:
    """One obstacle of a scene: its id (its name), the obstacle, where its gizmo was put."""

    id: str
    obstacle: Obstacle
    goal: np.ndarray


@dataclass(frozen=True)
class ForceSetup:
    """A scene's force control: the tissue, the setpoint along the tool's x, y, z (N) and
    which of those axes the force law holds."""

    tissue: TissueSurface
    setpoint: np.ndarray
    axes: tuple[bool, bool, bool]


@dataclass(frozen=True)
class Scene:
    """A checked scene (see the module docstring for the file format)."""

    robot: dict
    main: str
    ghost: str | None
    gain: float
    damping: float
    rate: float
    motion_scale: float
    ghost_offset: np.ndarray
    q: dict[str, np.ndarray]
    target_position: np.ndarray
    target_wxyz: np.ndarray
    constraints: tuple[PlacedConstraint, ...]
    #: every EE's target (position, unit wxyz), in ``robot.ee_frames`` order
    targets: tuple[tuple[np.ndarray, np.ndarray], ...] = ()
    #: weight of the EE twists' angular entries (``TeleopApp.set_orientation_weight``)
    orientation_weight: float = 1.0
    #: what the operator commands of each EE (``TeleopApp.set_task_mode``; docs/design.md
    #: section 20); a scene without one: ``auto``
    task_mode: str = "auto"
    #: whether the controllers keep the pairs apart, and the avoidance's settings
    #: (``CollisionAvoidance.to_dict()`` without its obstacles); None: a version 1 scene
    collisions: dict | None = None
    obstacles: tuple[PlacedObstacle, ...] = ()
    #: the force control's tissue and settings (None: no tissue placed); ``keep``: a
    #: version 1 or 2 scene, which leaves the page's force control as it is
    force: ForceSetup | None = None
    keep_force: bool = False


def _spec(value: Any, name: str, optional: bool = False) -> str | None:
    if value is None and optional:
        return None
    if not isinstance(value, str) or not value:
        raise ValueError(f"scene {name} must be a controller spec such as 'cjm' or "
                         f"'qp:daqp', got {value!r}")
    return value


def _target(data: Any, where: str) -> tuple[np.ndarray, np.ndarray]:
    """A scene target's position and unit quaternion (w, x, y, z)."""
    if not isinstance(data, Mapping):
        raise ValueError(f"scene {where} must be an object with 'position' and 'wxyz'")
    wxyz = as_vector(data.get("wxyz"), 4, f"scene {where}.wxyz")
    if np.linalg.norm(wxyz) < 1e-9:
        raise ValueError(f"scene {where}.wxyz must be a non-zero quaternion")
    return as_vector(data.get("position"), 3, f"scene {where}.position"), wxyz / np.linalg.norm(wxyz)


def _targets(data: Mapping, ee_frames: tuple[str, ...] | None) -> tuple:
    """Every EE's target: ``"targets"`` (one per frame of ``ee_frames``, in order), else
    ``"target"`` alone (a single-EE robot)."""
    entries = data.get("targets")
    if entries is None:
        if ee_frames is not None and len(ee_frames) > 1:
            raise ValueError(f"scene 'targets' must give one target per end effector "
                             f"{list(ee_frames)}")
        return (_target(data.get("target"), "target"),)
    if not isinstance(entries, list):
        raise ValueError("scene 'targets' must be a list, one target per end effector")
    frames = [entry.get("frame") if isinstance(entry, Mapping) else None for entry in entries]
    if ee_frames is not None and frames != list(ee_frames):
        raise ValueError(f"scene 'targets' must name the end effectors {list(ee_frames)} in "
                         f"order, got {frames}")
    return tuple(_target(entry, f"targets[{index}]") for index, entry in enumerate(entries))


def parse_scene(data: Any, nq: int | None = None, ee_frames: tuple[str, ...] | None = None
                ) -> Scene:
    """Check a scene (a dict from JSON); ``nq`` checks the configurations' size,
    ``ee_frames`` its targets (one per end effector)."""
    if not isinstance(data, Mapping):
        raise ValueError("a scene must be a JSON object")
    if data.get("format") != FORMAT:
        raise ValueError(f"not a scene file: 'format' must be {FORMAT!r}, "
                         f"got {short_repr(data.get('format'))}")
    if type(data.get("version")) is not int or data["version"] not in VERSIONS:  # True is not 1
        raise ValueError(f"scene version {short_repr(data.get('version'))} is not supported "
                         f"(this program reads versions {', '.join(map(str, VERSIONS))})")
    robot = check_robot_fields(data.get("robot"))
    controllers = data.get("controllers")
    if not isinstance(controllers, Mapping):
        raise ValueError("scene 'controllers' must be an object {'main': ..., 'ghost': ...}")
    main = _spec(controllers.get("main"), "controllers.main")
    ghost = _spec(controllers.get("ghost"), "controllers.ghost", optional=True)
    q_data = data.get("q")
    if not isinstance(q_data, Mapping) or "main" not in q_data:
        raise ValueError("scene 'q' must be an object with the 'main' configuration")
    size = nq if nq is not None else len(q_data["main"]) if isinstance(q_data["main"], list) else 0
    q = {"main": as_vector(q_data["main"], size, "scene q.main")}
    if ghost is not None:
        q["ghost"] = as_vector(q_data.get("ghost", q_data["main"]), size, "scene q.ghost")
    position, wxyz = _target(data.get("target"), "target")
    targets = _targets(data, ee_frames)
    placed = []
    entries = data.get("constraints", [])
    if not isinstance(entries, list):
        raise ValueError("scene 'constraints' must be a list")
    for index, entry in enumerate(entries):
        where = f"scene constraints[{index}]"
        if not isinstance(entry, Mapping) or not isinstance(entry.get("id"), str):
            raise ValueError(f"{where} must be an object with an 'id' and a 'constraint'")
        try:
            constraint = Constraint.from_dict(entry.get("constraint"))
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None
        goal = as_vector(entry.get("goal", constraint.position.tolist()), 3, f"{where}.goal")
        placed.append(PlacedConstraint(entry["id"], constraint, goal))
    ids = [p.id for p in placed]
    if len(set(ids)) != len(ids):
        raise ValueError(f"scene constraint ids must be unique, got {ids}")
    collisions, obstacles = _collisions(data)
    return Scene(
        robot=dict(robot), main=main, ghost=ghost,
        gain=as_number(data.get("gain"), "scene gain", 0.0),
        damping=as_number(data.get("damping", 0.0), "scene damping", 0.0, maximum=MAX_DAMPING),
        rate=as_number(data.get("rate"), "scene rate", positive=True, maximum=MAX_RATE_HZ),
        motion_scale=as_number(data.get("motion_scale", 1.0), "scene motion_scale", positive=True),
        ghost_offset=as_vector(data.get("ghost_offset", [0.0, 0.0, 0.0]), 3, "scene ghost_offset"),
        q=q, target_position=position, target_wxyz=wxyz, constraints=tuple(placed),
        targets=targets,
        orientation_weight=as_number(data.get("orientation_weight", 1.0),
                                     "scene orientation_weight", 0.0, maximum=1.0),
        task_mode=_task_mode(data.get("task_mode", AUTO)),
        collisions=collisions, obstacles=obstacles, force=_force(data),
        keep_force=data["version"] < 3)


def _force(data: Mapping) -> ForceSetup | None:
    """A scene's force control (None: no tissue, or a scene before version 3)."""
    if data["version"] < 3:
        if "force" in data:
            raise ValueError(f"scene 'force' needs version 3, the file says version "
                             f"{data['version']}")
        return None
    entry = data.get("force")
    if entry is None:
        return None
    if not isinstance(entry, Mapping) or set(entry) != {"tissue", "setpoint", "axes"}:
        raise ValueError("scene 'force' must be null or an object with 'tissue', 'setpoint' "
                         "and 'axes'")
    tissue = TissueSurface.from_dict(entry["tissue"], "scene force.tissue")
    setpoint = as_vector(entry["setpoint"], 3, "scene force.setpoint",
                         maximum=MAX_FORCE_SETPOINT_N)
    axes = entry["axes"]
    if not (isinstance(axes, list) and len(axes) == 3
            and all(isinstance(axis, bool) for axis in axes) and any(axes)):
        raise ValueError(f"scene force.axes must be 3 booleans, at least one true, got "
                         f"{short_repr(axes)}")
    return ForceSetup(tissue, setpoint, (axes[0], axes[1], axes[2]))


def _task_mode(mode: object) -> str:
    """A scene's task mode: ``auto`` or a mode of ``TASK_MODES``, else ``ValueError``."""
    if mode != AUTO:
        task_mode(mode)
    return str(mode)


#: the keys of a scene's ``"collisions"``: ``on`` and the avoidance's settings
COLLISION_KEYS = ("on", "self_collision", "safety_distance", "detection_distance",
                  "approach_speed", "disabled_pairs", "extra_pairs", "response_time")


def _collisions(data: Mapping) -> tuple[dict | None, tuple[PlacedObstacle, ...]]:
    """A scene's collision settings (None in a version 1 scene) and its obstacles; the
    settings' values are checked when the avoidance is built on the robot
    (``CollisionAvoidance.from_dict``)."""
    if data["version"] == 1:
        for key in ("collisions", "obstacles"):
            if key in data:
                raise ValueError(f"scene {key!r} needs version 2, the file says version 1")
        return None, ()
    settings = data.get("collisions")
    if not isinstance(settings, Mapping):
        raise ValueError("scene 'collisions' must be an object with 'on' and the collision "
                         "settings")
    unknown = sorted(set(settings) - set(COLLISION_KEYS))
    if unknown:
        raise ValueError(f"unknown scene collisions field {unknown[0]!r} (its fields: "
                         f"{', '.join(COLLISION_KEYS)})")
    if not isinstance(settings.get("on"), bool):
        raise ValueError(f"scene collisions.on must be true or false, got "
                         f"{short_repr(settings.get('on'))}")
    entries = data.get("obstacles", [])
    if not isinstance(entries, list):
        raise ValueError("scene 'obstacles' must be a list")
    placed = []
    for index, entry in enumerate(entries):
        where = f"scene obstacles[{index}]"
        if not isinstance(entry, Mapping) or not isinstance(entry.get("id"), str) \
                or not entry["id"].strip():
            raise ValueError(f"{where} must be an object with an 'id' and an 'obstacle'")
        try:
            obstacle = Obstacle.from_dict(entry.get("obstacle"))
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None
        obstacle.name = entry["id"]
        goal = as_vector(entry.get("goal", obstacle.position.tolist()), 3, f"{where}.goal")
        placed.append(PlacedObstacle(entry["id"], obstacle, goal))
    ids = [p.id for p in placed]
    if len(set(ids)) != len(ids):
        raise ValueError(f"scene obstacle ids must be unique, got {ids}")
    return dict(settings), tuple(placed)


def read_scene_file(path: str | Path) -> dict:
    """The JSON object of a scene file; a missing or unreadable file is one ``ValueError``."""
    path = Path(path).expanduser()
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"no scene file at {str(path)!r}") from None
    except OSError as error:
        raise ValueError(f"cannot read scene file {str(path)!r}: {error.strerror}") from None
    return parse_json(text, f"scene file {str(path)!r}")


def write_scene_file(path: str | Path, scene: dict) -> Path:
    """Write ``scene`` as indented JSON (folders created), replacing the name, never
    writing through a link (:func:`teleop.files.replace_file`); an unwritable path is a
    ``ValueError`` with the reason."""
    path = Path(path).expanduser()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        replace_file(path, json.dumps(scene, indent=1) + "\n")
    except OSError as error:
        raise ValueError(f"cannot write scene file {str(path)!r}: {error.strerror}") from None
    return path
