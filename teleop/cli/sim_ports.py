"""Where ``teleop sim --ros2``'s walls are (docs/ros2.md, "A simulated robot"): the holes
of a named scenario (``--scenario``, the ones ``teleop compare`` runs) or of a scene saved
from the page (``--scene``, its ``constraints``), and the start they come with."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from constraints import Constraint
from constraints.validation import as_vector
from teleop.json_text import parse_json
from teleop.robots import Robot, load_robot

#: the robot served when neither --robot nor --scenario names one
DEFAULT_ROBOT = "ur5_instrument"


def add_port_options(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--scenario``, ``--scene`` and ``--port-forces`` on ``parser``."""
    parser.add_argument("--scenario", metavar="NAME",
                        help="place the holes of this teleop compare scenario and start at "
                             "its q0, on its robot (default: no port)")
    parser.add_argument("--scene", metavar="FILE",
                        help="place the constraints of a scene saved from teleop web and "
                             "start at its main robot's q (default: no port)")
    parser.add_argument("--port-forces", default="/port_forces", metavar="NAMESPACE",
                        help="each port's wall force (geometry_msgs/WrenchStamped, world "
                             "frame) on NAMESPACE/port<i> (default: /port_forces)")


def _scene_constraints(path: str, robot_name: str, robot: Robot
                       ) -> tuple[list[Constraint], np.ndarray | None]:
    """The constraints and the main robot's ``q`` of the scene file at ``path``;
    ``ValueError`` naming the file for one that cannot be read, another robot, or a
    constraint or configuration that does not parse or lies outside the joint limits."""
    where = f"scene file {path!r}"
    try:
        text = Path(path).expanduser().read_text(encoding="utf-8")
    except OSError as error:
        raise ValueError(f"cannot read {where}: {error.strerror}") from None
    scene = parse_json(text, where)
    if not isinstance(scene, dict):
        raise ValueError(f"{where} does not hold a JSON object")
    entry = scene.get("robot")
    source = entry.get("source") if isinstance(entry, dict) else None
    if not isinstance(source, str):
        raise ValueError(f"{where} names no robot (its robot.source)")
    if source != robot_name:
        raise ValueError(f"{where} is a scene of robot {source!r}: give --robot {source}")
    placed = scene.get("constraints", [])
    if not isinstance(placed, list) or not all(isinstance(p, dict) for p in placed):
        raise ValueError(f"{where}: constraints must be a list of objects")
    constraints = [Constraint.from_dict(p.get("constraint")) for p in placed]
    q = scene.get("q", {}).get("main") if isinstance(scene.get("q"), dict) else None
    if q is None:
        return constraints, None
    model = robot.model
    q0 = as_vector(q, model.nq, f"{where}: q.main")
    outside = np.flatnonzero((q0 < model.lowerPositionLimit - 1e-9)
                             | (q0 > model.upperPositionLimit + 1e-9))
    if outside.size:
        joints = [name for joint, name in enumerate(model.names) if joint > 0
                  and any(model.idx_qs[joint] <= i < model.idx_qs[joint] + model.nqs[joint]
                          for i in outside.tolist())]
        raise ValueError(f"{where}: q.main is outside the joint limits of {joints}")
    return constraints, q0


def sim_ports(args: argparse.Namespace) -> tuple[Robot, list[Constraint], np.ndarray | None]:
    """The robot, the constraints and the start (None: ``--q0``'s or the robot's home)
    the options ask for; ``ValueError`` for both ``--scenario`` and ``--scene``."""
    if args.scenario is not None and args.scene is not None:
        raise ValueError("--scenario and --scene both place the ports: give one")
    if args.scenario is not None:
        from teleop.experiments.contact_compare import refuse_contact_scenario
        from teleop.experiments.scenarios import load_scenario

        refuse_contact_scenario(args.scenario, "teleop sim")
        plan = load_scenario(args.scenario, None if args.robot is None else load_robot(args.robot))
        return plan.robot, plan.make_constraints(), plan.q0.copy()
    robot = load_robot(args.robot or DEFAULT_ROBOT)
    if args.scene is None:
        return robot, [], None
    return (robot, *_scene_constraints(args.scene, robot_name(args), robot))


def robot_name(args: argparse.Namespace) -> str:
    """The robot the options name."""
    return args.robot or DEFAULT_ROBOT
