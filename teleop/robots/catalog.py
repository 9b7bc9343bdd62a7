"""Where a robot comes from: the built-in URDFs and those of the installed
example-robot-data wheel (``teleop robots`` lists both), and which joints of a URDF move
nothing the controllers are asked about (grippers, fingers), locked by default on the
command line (docs/cli.md)."""

from __future__ import annotations

import importlib.metadata
import warnings
from pathlib import Path
from typing import Any, Sequence

from .robot import BUILTIN_ROBOTS, Robot, load_robot

#: The distribution that installs the example robots, and where, inside its cmeel prefix,
#: its URDFs sit (``<site-packages>/cmeel.prefix/share/example-robot-data/robots``).
EXAMPLE_ROBOT_DATA = "example-robot-data"
EXAMPLE_ROBOTS_FOLDER = "cmeel.prefix/share/example-robot-data/robots"


def example_robot_data_share() -> Path | None:
    """The ``share`` folder example-robot-data installs into (its URDFs' ``package://``
    root), or None when the wheel is not installed."""
    try:
        distribution = importlib.metadata.distribution(EXAMPLE_ROBOT_DATA)
    except importlib.metadata.PackageNotFoundError:
        return None
    robots = Path(str(distribution.locate_file(EXAMPLE_ROBOTS_FOLDER)))
    return robots.parent.parent if robots.is_dir() else None


def installed_urdfs() -> dict[str, Path]:
    """The URDFs of the installed example-robot-data by name (the file's stem, e.g.
    ``panda``, ``ur5_robot``), sorted; empty when the wheel is not installed."""
    share = example_robot_data_share()
    if share is None:
        return {}
    found = sorted((share / "example-robot-data/robots").rglob("*.urdf"))
    return {path.stem: path for path in found}


def robot_source(name_or_path: str) -> str | Path:
    """What ``load_robot`` takes for ``name_or_path``: a built-in robot's name, a URDF
    file, or the name of an installed example-robot-data URDF (``panda``); ``ValueError``
    naming the choices otherwise."""
    if name_or_path in BUILTIN_ROBOTS or Path(name_or_path).expanduser().is_file():
        return name_or_path
    installed = installed_urdfs()
    if name_or_path in installed:
        return installed[name_or_path]
    if name_or_path.endswith(".urdf") or "/" in name_or_path:  # meant as a file
        raise ValueError(f"no URDF file at {name_or_path!r}")
    raise ValueError(f"no robot {name_or_path!r}: not a built-in robot ({', '.join(BUILTIN_ROBOTS)}), "
                     "not a URDF file and not an installed example-robot-data URDF "
                     "('teleop robots' lists them)")


def joints_off_the_path(robot: Robot) -> list[str]:
    """The movable joints that carry none of the robot's end-effector frames nor its
    constrained links (a gripper's fingers beside the hand): moving them changes nothing
    a controller is asked about, so the command line locks them unless told otherwise."""
    model = robot.model
    frames = (*robot.ee_frames, *robot.constrained_links)
    on_path = {joint for name in frames
               for joint in model.supports[model.frames[model.getFrameId(name)].parentJoint]}
    return [model.names[joint] for joint in range(1, model.njoints)
            if joint not in on_path and model.nvs[joint] > 0]


#: ``locked_joints`` naming no joint: every movable joint controlled, the default locks
#: dropped.
NO_JOINT = "none"


def load_robot_choice(robot: str | None, default: str, *, ee_frame: str | None = None,
                      constrained_link: str | None = None, link_axis: Any = None,
                      package_dirs: Sequence[str] | None = None, q_home: Any = None,
                      locked_joints: Sequence[str] | None = None) -> Robot:
    """The robot a command's robot options ask for (``default`` when ``robot`` is None;
    ``robot`` as :func:`robot_source` reads it). Without ``locked_joints``, a URDF's joints
    off the path to its end effectors and constrained links are locked
    (:func:`joints_off_the_path`: the Panda's fingers, nq 9 -> 7); ``[NO_JOINT]`` locks none."""
    source = robot_source(robot or default)
    options = dict(ee_frame=ee_frame, constrained_link=constrained_link, link_axis=link_axis,
                   package_dirs=package_dirs, q_home=q_home)
    if locked_joints is not None and list(locked_joints) == [NO_JOINT]:
        return load_robot(source, **options)
    if locked_joints is not None or source in BUILTIN_ROBOTS:
        return load_robot(source, locked_joints=locked_joints, **options)
    with warnings.catch_warnings():  # the full model only names the joints: warn once, below
        warnings.simplefilter("ignore")
        whole = load_robot(source, **{**options, "q_home": None})
    return load_robot(source, locked_joints=joints_off_the_path(whole) or None, **options)
