"""The plant's options (docs/cli.md): which robot the loop drives, ``kinematic``,
``mujoco`` with its physics settings or ``ros2`` with its topics (docs/ros2.md), and the
abdominal wall's stiffness; shared by compare, replay, record and bench."""

from __future__ import annotations

import argparse

from teleop.limits import (
    MAX_INTERFACE_JERK,
    MAX_JOINT_FRICTION,
    MAX_PHYSICS_RATE_HZ,
    MAX_SERVO_BANDWIDTH_HZ,
    MIN_PHYSICS_RATE_HZ,
)
from teleop.options import PAYLOAD, PLANT_KINDS, WALL_STIFFNESS

from .arguments import bounded
from .ros2_options import add_ros2_options, given_ros2_options, ros2_settings

friction = bounded(float, 0.0, MAX_JOINT_FRICTION)
physics_rate = bounded(float, MIN_PHYSICS_RATE_HZ, MAX_PHYSICS_RATE_HZ, unit="Hz")
servo_bandwidth = bounded(float, 0.0, MAX_SERVO_BANDWIDTH_HZ, inclusive_minimum=False, unit="Hz")
interface_jerk = bounded(float, 0.0, MAX_INTERFACE_JERK, inclusive_minimum=False, unit="rad/s^3")

#: The physics plant's options: (option, the PlantSettings field) (docs/cli.md).
PLANT_OPTIONS = (("--payload", "payload"), ("--coulomb-friction", "coulomb_friction"),
                 ("--viscous-friction", "viscous_friction"), ("--physics-rate", "physics_rate"),
                 ("--servo-bandwidth", "servo_bandwidth"),
                 ("--interface-limits", "interface_limits"),
                 ("--interface-jerk-limit", "interface_jerk_limit"))


def add_plant_options(parser: argparse.ArgumentParser, base: str) -> None:
    """``--plant`` and its knobs; ``base`` says what an option left out means."""
    plant = parser.add_argument_group(
        "the plant", "the robot the loop drives, the same for every controller "
        "(docs/design.md section 17); an option left out: " + base)
    plant.add_argument("--plant", choices=PLANT_KINDS,
                       help="kinematic: the ideal integrator q += qd dt; mujoco: the URDF "
                       "simulated in MuJoCo, servoed drives, a wall at every hole; ros2: a "
                       "robot over ROS 2, its options below (docs/ros2.md) "
                       "(default: kinematic)")
    add_ros2_options(plant)
    WALL_STIFFNESS.add_to(plant, left_out="each hole's own, 1 N/mm")
    PAYLOAD.add_to(plant, left_out="0")
    plant.add_argument("--coulomb-friction", type=friction, metavar="NM",
                       help=f"dry friction of every joint, at most {MAX_JOINT_FRICTION:g} (mujoco; "
                       "default: 0)")
    plant.add_argument("--viscous-friction", type=friction, metavar="NMS",
                       help="viscous friction of every joint (N m s/rad), at most "
                       f"{MAX_JOINT_FRICTION:g} (mujoco; default: 0)")
    plant.add_argument("--physics-rate", type=physics_rate, metavar="HZ",
                       help=f"physics steps per second, in [{MIN_PHYSICS_RATE_HZ:g}, "
                       f"{MAX_PHYSICS_RATE_HZ:g}] (mujoco; default: {MIN_PHYSICS_RATE_HZ:g})")
    plant.add_argument("--servo-bandwidth", type=servo_bandwidth, metavar="HZ",
                       help="natural frequency of each joint's position servo, at most "
                       f"{MAX_SERVO_BANDWIDTH_HZ:g} (mujoco; default: 20)")
    plant.add_argument("--interface-limits", choices=("off", "count", "strict"),
                       help="the robot's velocity interface checks each command's joint "
                       "acceleration against the robot's limits (and the jerk against "
                       "--interface-jerk-limit), 1%% tolerance: count counts the faults, "
                       "strict stops the robot at the first, as a Franka's reflex does "
                       "(mujoco; default: off)")
    plant.add_argument("--interface-jerk-limit", type=interface_jerk, metavar="RAD_PER_S3",
                       help="the interface's jerk limit of every joint, at most "
                       f"{MAX_INTERFACE_JERK:g} (mujoco, with --interface-limits; default: none)")


def plant_choice(args: argparse.Namespace, base=None):
    """The plant the options ask for, over ``base`` (a ``PlantChoice``: a session's; None:
    the kinematic plant): each option given replaces ``base``'s value (``--plant
    kinematic`` drops its physics settings). ``ValueError`` for a physics option on the
    kinematic plant."""
    from dataclasses import replace

    from teleop.plants.choice import PlantChoice

    base = base or PlantChoice()
    kind = args.plant or base.kind
    given = [(option, name) for option, name in PLANT_OPTIONS
             if getattr(args, name) is not None]
    if kind != "mujoco" and given:
        raise ValueError(f"{', '.join(option for option, _ in given)} "
                         f"need{'s' * (len(given) == 1)} --plant mujoco (the {kind} plant "
                         "is not simulated here)")
    ros2_given = given_ros2_options(args)
    if kind != "ros2" and ros2_given:
        raise ValueError(f"{', '.join(ros2_given)} need{'s' * (len(ros2_given) == 1)} "
                         "--plant ros2")
    from teleop.plants import PlantSettings

    physics = base.settings if kind == "mujoco" else PlantSettings()  # none on kinematic
    settings = replace(physics, **{name: getattr(args, name) for _, name in given})
    stiffness = base.wall_stiffness if args.wall_stiffness is None else args.wall_stiffness * 1e3
    ros2 = (ros2_settings(args) if ros2_given or base.kind != "ros2" else base.ros2
            ) if kind == "ros2" else None
    return PlantChoice(kind, settings, stiffness, ros2)
