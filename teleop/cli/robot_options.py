"""The robot options every command that runs a robot takes (``teleop compare``,
``record``, ``sweep``, and ``teleop web`` from the layer above), and the one loader that
reads them (docs/cli.md)."""

from __future__ import annotations

import argparse
from typing import Any

from teleop.robots import BUILTIN_ROBOTS, Robot
from teleop.robots.catalog import NO_JOINT, load_robot_choice

from .arguments import csv_list, numbers

#: The options' destinations, in the order they are added.
ROBOT_OPTIONS = ("robot", "ee_frame", "constrained_link", "link_axis", "package_dirs", "q_home",
                 "locked_joints")


def add_robot_arguments(group: argparse._ActionsContainer, default: str) -> None:
    """``--robot`` (its default described by ``default``), ``--ee-frame``,
    ``--constrained-link``, ``--link-axis``, ``--locked-joints``, ``--package-dirs``,
    ``--q-home`` (each None when left out)."""
    group.add_argument("--robot",
                       help=f"built-in robot ({', '.join(BUILTIN_ROBOTS)}), the path of a URDF or "
                            f"the name of an installed example-robot-data URDF ('teleop robots') "
                            f"(default: {default})")
    group.add_argument("--ee-frame", metavar="FRAME",
                       help="end-effector frame (default: the built-in robot's, else the URDF's "
                            "last link)")
    group.add_argument("--constrained-link", metavar="LINK",
                       help="link the constraints act on (default: the built-in robot's, else "
                            "none: no constraint can be placed on an arm)")
    group.add_argument("--link-axis", nargs=3, type=float, metavar=("X", "Y", "Z"),
                       help="long direction of the constrained link in its own coordinates "
                            "(default: the built-in robot's, else 0 0 1)")
    group.add_argument("--locked-joints", type=csv_list, metavar="JOINT[,JOINT...]",
                       help="URDF joints to freeze at their --q-home values (grippers, a "
                            f"torso): no controller sees or moves them; '{NO_JOINT}' freezes "
                            "none (default: a URDF's joints that carry neither the end "
                            "effector nor the constrained link, e.g. a gripper's fingers)")
    group.add_argument("--package-dirs", action="append", type=csv_list, metavar="DIR[,DIR...]",
                       help="where package:// meshes are looked up; repeatable (default: the "
                            "URDF's folder and its ancestors)")
    group.add_argument("--q-home", type=numbers, metavar="Q1,Q2,...",
                       help="home configuration, nq numbers of the URDF's joints (the locked "
                            "ones included); write --q-home=-0.5,... when the first is negative "
                            "(default: the built-in robot's, else the neutral configuration "
                            "clipped to the limits)")


def robot_options_given(args: argparse.Namespace) -> list[str]:
    """The robot options given, as written (``--ee-frame``)."""
    return [f"--{name.replace('_', '-')}" for name in ROBOT_OPTIONS
            if getattr(args, name, None) is not None]


def robot_from_arguments(args: argparse.Namespace, default: str) -> Robot:
    """The robot the options ask for (``default`` when ``--robot`` is left out):
    :func:`teleop.robots.catalog.load_robot_choice`, a gripper's joints locked by default."""
    return load_robot_choice(args.robot, default, **robot_settings(args))


def robot_settings(args: argparse.Namespace) -> dict[str, Any]:
    """The options but ``--robot`` as ``load_robot_choice``'s keywords (``--package-dirs
    a,b --package-dirs c`` -> ``[a, b, c]``)."""
    package_dirs = None
    if args.package_dirs is not None:
        package_dirs = [directory for group in args.package_dirs for directory in group]
    return dict(ee_frame=args.ee_frame, constrained_link=args.constrained_link,
                link_axis=args.link_axis, package_dirs=package_dirs, q_home=args.q_home,
                locked_joints=args.locked_joints)
