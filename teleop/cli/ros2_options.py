"""The ROS 2 robot's options (docs/ros2.md): where its joint states come from and its
commands go, the domain; shared by ``teleop sim --ros2`` and every ``--plant ros2``."""

from __future__ import annotations

import argparse

from teleop.limits import MAX_RESPONSE_TIME_S
from teleop.plants.ros2.settings import DEFAULT_RESPONSE_TIME, Ros2Settings

from .arguments import bounded

#: (option, attribute) of the ROS 2 options.
ROS2_OPTIONS = (("--joint-states", "joint_states"), ("--command-topic", "command_topic"),
                ("--command-joints", "command_joints"), ("--crtk", "crtk"),
                ("--ros-domain", "ros_domain"), ("--realtime-priority", "realtime_priority"),
                ("--response-time", "response_time"))


def add_ros2_options(parser: argparse.ArgumentParser | argparse._ArgumentGroup,
                     driven: bool = True) -> None:
    """The options of :data:`ROS2_OPTIONS` on ``parser``; without ``driven`` (``teleop
    sim --ros2``, which plays the robot) not ``--response-time``, the driven robot's."""
    parser.add_argument("--joint-states", metavar="TOPIC",
                        help="the robot's sensor_msgs/JointState topic (default: /joint_states)")
    parser.add_argument("--command-topic", metavar="TOPIC",
                        help="the JointGroupVelocityController's Float64MultiArray topic "
                             "(default: /forward_velocity_controller/commands)")
    parser.add_argument("--command-joints", metavar="NAMES",
                        help="comma-separated: the controller's 'joints' parameter, the "
                             "commands' order (default: the robot model's joint order)")
    parser.add_argument("--crtk", metavar="NAMESPACE",
                        help="a CRTK robot instead: NAMESPACE/measured_js, /servo_jv, "
                             "/operating_state (default: ros2_control)")
    parser.add_argument("--ros-domain", type=int, metavar="N",
                        help="ROS 2 domain id, 0-232 (default: ROS_DOMAIN_ID, else 0)")
    parser.add_argument("--realtime-priority", type=int, metavar="N",
                        help="SCHED_FIFO priority 1-99 of the threads on the wire, as "
                             "ros2_control's controller_manager runs; 0: ordinary scheduling "
                             "(default: 40, below the controller_manager's 50; teleop sim "
                             "--ros2, which plays the robot: 50; without the privilege they "
                             "stay ordinary and the measures say so)")
    if driven:
        parser.add_argument("--response-time", type=bounded(float, 0.0, MAX_RESPONSE_TIME_S,
                                                            unit="s"), metavar="S",
                            help="how late the robot follows a velocity command (its servos' "
                                 "time constant), what the collision damper counts on, as "
                                 "1/(2 pi servo bandwidth) on the mujoco plant (default: "
                                 f"{DEFAULT_RESPONSE_TIME:.4g}, a 20 Hz servo's)")


def given_ros2_options(args: argparse.Namespace) -> list[str]:
    """The ROS 2 options given on the command line."""
    return [option for option, name in ROS2_OPTIONS if getattr(args, name, None) is not None]


def ros2_settings(args: argparse.Namespace) -> Ros2Settings:
    """The settings the options ask for (``ValueError`` naming the one refused)."""
    settings = {"joint_states": args.joint_states, "command_topic": args.command_topic,
                "crtk": args.crtk, "domain": args.ros_domain,
                "realtime_priority": args.realtime_priority,
                "response_time": getattr(args, "response_time", None),
                "command_joints": (None if args.command_joints is None else
                                   tuple(n.strip() for n in args.command_joints.split(",")
                                         if n.strip()))}
    return Ros2Settings(**{name: value for name, value in settings.items() if value is not None})
