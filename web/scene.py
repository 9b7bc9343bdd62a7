"""Scenes: what an operator set up in the browser, as one JSON file.

A scene holds the robot (a built-in name or a URDF path with its options), the placed
constraints (each its ``Constraint.to_dict()``, with its id and where its gizmo was put),
the robots' configurations, the target, the controller specs, the drift gain, the damping,
the control rate, the motion scale and the ghost's offset::

    {"format": "cjm-teleop-scene", "version": 1,
     "robot": {"source": "sda10f", "ee_frame": "tool0", "constrained_link": "arm_link_5_r",
               "link_axis": [0, 0, -1], "package_dirs": null, "q_home": [...]},
     "controllers": {"main": "cjm", "ghost": "qp:daqp"},
     "gain": 100.0, "damping": 0.0, "rate": 1000.0, "motion_scale": 1.0,
     "ghost_offset": [0.0, 0.9, 0.0],
     "q": {"main": [...], "ghost": [...]},
     "target": {"position": [x, y, z], "wxyz": [w, x, y, z]},
     "constraints": [{"id": "hole-1", "goal": [x, y, z], "constraint": {"kind": "hole", ...}}]}

:func:`parse_scene` checks a scene and turns it into a :class:`Scene`; anything wrong raises
``ValueError`` naming the field (the UI shows it as a notification, the CLI as one line).
Applying a scene to a running app is :meth:`web.app.TeleopApp.apply_scene`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from constraints import Constraint
from constraints.validation import as_number, as_vector
from teleop.robots import BUILTIN_ROBOTS, Robot, load_robot

FORMAT = "cjm-teleop-scene"
VERSION = 1


def robot_source(robot: Robot) -> str:
    """A built-in robot's name, else the path of its URDF."""
    if robot.name in BUILTIN_ROBOTS and robot.urdf_path.parent.name == "robots":
        return robot.name
    return str(robot.urdf_path)


def robot_to_dict(robot: Robot) -> dict:
    """Everything :func:`load_robot` needs to load ``robot`` again."""
    source = robot_source(robot)
    builtin = source in BUILTIN_ROBOTS
    return {"source": source, "ee_frame": robot.ee_frame,
            "constrained_link": robot.constrained_link,
            "link_axis": [float(x) for x in robot.link_axis],
            "package_dirs": None if builtin else list(robot.package_dirs),
            "q_home": [float(x) for x in robot.q_home]}


def robot_from_dict(data: Any) -> Robot:
    """Load the robot a scene names (``FileNotFoundError`` or ``ValueError`` if it cannot be)."""
    if not isinstance(data, Mapping) or not isinstance(data.get("source"), str):
        raise ValueError("scene 'robot' must be an object with a 'source' (a built-in robot "
                         "name or a URDF path)")
    return load_robot(data["source"], ee_frame=data.get("ee_frame"),
                      constrained_link=data.get("constrained_link"),
                      link_axis=data.get("link_axis"), package_dirs=data.get("package_dirs"),
                      q_home=data.get("q_home"))


def same_robot(robot: Robot, data: Mapping) -> bool:
    """Whether the scene's robot description is ``robot`` (same source, frames and axis)."""
    mine = robot_to_dict(robot)
    if data.get("source") != mine["source"]:
        return False
    for key in ("ee_frame", "constrained_link"):
        if data.get(key, mine[key]) != mine[key]:
            return False
    axis = data.get("link_axis")
    return axis is None or np.allclose(np.asarray(axis, dtype=float), robot.link_axis)


@dataclass(frozen=True)
class PlacedConstraint:
    """One constraint of a scene: its id, the constraint, where its gizmo was put."""

    id: str
    constraint: Constraint
    goal: np.ndarray


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


def _spec(value: Any, name: str, optional: bool = False) -> str | None:
    if value is None and optional:
        return None
    if not isinstance(value, str) or not value:
        raise ValueError(f"scene {name} must be a controller spec such as 'cjm' or "
                         f"'qp:daqp', got {value!r}")
    return value


def parse_scene(data: Any, nq: int | None = None) -> Scene:
    """Check a scene (a dict from JSON); ``nq`` checks the configurations' size."""
    if not isinstance(data, Mapping):
        raise ValueError("a scene must be a JSON object")
    if data.get("format") != FORMAT:
        raise ValueError(f"not a scene file: 'format' must be {FORMAT!r}, "
                         f"got {data.get('format')!r}")
    if data.get("version") != VERSION:
        raise ValueError(f"scene version {data.get('version')!r} is not supported "
                         f"(this program reads version {VERSION})")
    robot = data.get("robot")
    if not isinstance(robot, Mapping) or not isinstance(robot.get("source"), str):
        raise ValueError("scene 'robot' must be an object with a 'source'")
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
    target = data.get("target")
    if not isinstance(target, Mapping):
        raise ValueError("scene 'target' must be an object with 'position' and 'wxyz'")
    wxyz = as_vector(target.get("wxyz"), 4, "scene target.wxyz")
    if np.linalg.norm(wxyz) < 1e-9:
        raise ValueError("scene target.wxyz must be a non-zero quaternion")
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
    return Scene(
        robot=dict(robot), main=main, ghost=ghost,
        gain=as_number(data.get("gain"), "scene gain", 0.0),
        damping=as_number(data.get("damping", 0.0), "scene damping", 0.0),
        rate=as_number(data.get("rate"), "scene rate", positive=True),
        motion_scale=as_number(data.get("motion_scale", 1.0), "scene motion_scale", positive=True),
        ghost_offset=as_vector(data.get("ghost_offset", [0.0, 0.0, 0.0]), 3, "scene ghost_offset"),
        q=q, target_position=as_vector(target.get("position"), 3, "scene target.position"),
        target_wxyz=wxyz / np.linalg.norm(wxyz), constraints=tuple(placed))


def read_scene_file(path: str | Path) -> dict:
    """The JSON object of a scene file; a missing or unreadable file is one ``ValueError``."""
    path = Path(path).expanduser()
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ValueError(f"no scene file at {str(path)!r}") from None
    except OSError as error:
        raise ValueError(f"cannot read scene file {str(path)!r}: {error.strerror}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"scene file {str(path)!r} is not JSON: {error}") from None


def write_scene_file(path: str | Path, scene: dict) -> Path:
    """Write ``scene`` as indented JSON (folders created); an unwritable path is a
    ``ValueError`` with the reason."""
    path = Path(path).expanduser()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(scene, indent=1) + "\n", encoding="utf-8")
    except OSError as error:
        raise ValueError(f"cannot write scene file {str(path)!r}: {error.strerror}") from None
    return path
