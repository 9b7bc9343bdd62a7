"""The plants' options, each declared once (docs/cli.md, docs/design.md section 17): its
:class:`~teleop.options.SharedOption` (name, value, help, the commands that take it), the
plants that take it, and the field of the plant's settings it sets.

Every front end reads them from here: the argparse options of ``teleop compare``,
``replay``, ``record``, ``bench``, ``sim`` and ``teleop web`` are generated from
:data:`PLANT_OPTIONS` (:mod:`teleop.cli.plant_options`), a sweep's spec checks its plant
fields with the same validators (:mod:`teleop.experiments.sweep.spec`), the options given
become a :class:`~teleop.plants.PlantChoice` in one place
(:meth:`~teleop.plants.PlantChoice.with_options`), and :class:`PlantSettings` checks its
declared fields with them too (a session's header and the Python API). A new plant option
is one entry here and the field it sets; a new plant, its settings and its entries.
"""

from __future__ import annotations

from dataclasses import dataclass

from teleop.limits import (
    MAX_INTERFACE_JERK,
    MAX_JOINT_FRICTION,
    MAX_PAYLOAD_KG,
    MAX_PHYSICS_RATE_HZ,
    MAX_RESPONSE_TIME_S,
    MAX_SERVO_BANDWIDTH_HZ,
    MAX_WALL_STIFFNESS,
    MIN_PHYSICS_RATE_HZ,
)
from teleop.options import (BENCH, COMPARE, PLANT_KINDS, RECORD, REPLAY, RUNS, SIM, SWEEP, WEB,
                            Choice, Names, NumberRange, SharedOption, Text)

from .interface import INTERFACE_MODES
from .ros2.names import MAX_DOMAIN_ID
from .ros2.realtime import MAX_PRIORITY
from .ros2.settings import DEFAULT_RESPONSE_TIME

#: What a :class:`PlantOption` sets: a field of the :class:`~teleop.plants.PlantChoice`
#: itself, of its physics settings (:class:`~teleop.plants.PlantSettings`) or of its ROS 2
#: settings (:class:`~teleop.plants.ros2.settings.Ros2Settings`).
HOLDERS = ("plant", "physics", "ros2")

#: ``--plant``: the robot the loop drives.
PLANT = SharedOption(
    "plant", Choice(PLANT_KINDS), None,
    "kinematic: the ideal integrator q += qd dt; mujoco: the URDF simulated in MuJoCo, "
    "servoed drives, the abdominal wall at every hole; ros2: a robot over ROS 2, its "
    "options below (docs/ros2.md)", RUNS)


@dataclass(frozen=True)
class PlantOption:
    """One option of the plants: the ``option`` (what the front ends read), the
    ``plants`` that take it (any other refuses it, naming it), and the ``field`` of the
    ``holder`` (:data:`HOLDERS`) it sets, in the option's unit times ``scale``.
    ``left_out``: what leaving it out means, when the field's default does not say it
    (None, an empty list)."""

    option: SharedOption
    plants: tuple[str, ...]
    holder: str
    field: str
    scale: float = 1.0
    left_out: str = ""

    @property
    def name(self) -> str:
        """The option's name (``"payload"``)."""
        return self.option.name

    def __post_init__(self) -> None:
        if self.holder not in HOLDERS or not set(self.plants) <= set(PLANT_KINDS):
            raise ValueError(f"{self.name}: holder must be one of {', '.join(HOLDERS)} and "
                             f"plants of {', '.join(PLANT_KINDS)}")


#: The commands that take the physics plant's options.
PHYSICS_COMMANDS = frozenset((COMPARE, REPLAY, RECORD, BENCH, WEB))
#: The commands that take the ROS 2 robot's options (``teleop sim --ros2`` plays it).
ROS2_COMMANDS = frozenset((COMPARE, REPLAY, RECORD, BENCH, WEB, SIM))


def _physics(name: str, value: NumberRange | Choice, metavar: str | None, help_text: str,
             commands: frozenset[str] = PHYSICS_COMMANDS, left_out: str = "") -> PlantOption:
    return PlantOption(SharedOption(name, value, metavar, help_text, commands), ("mujoco",),
                       "physics", name, left_out=left_out)


def _ros2(name: str, value: Text | Names | NumberRange, metavar: str, help_text: str,
          field: str | None = None, left_out: str = "") -> PlantOption:
    return PlantOption(SharedOption(name, value, metavar, help_text, ROS2_COMMANDS), ("ros2",),
                       "ros2", field or name, left_out=left_out)


#: Every plant option, in the order of the command lines' help.
PLANT_OPTIONS: tuple[PlantOption, ...] = (
    PlantOption(SharedOption(
        "wall_stiffness", NumberRange(float, 0.0, MAX_WALL_STIFFNESS / 1e3, unit="N/mm"),
        "N_PER_MM", "lateral stiffness of the abdominal wall at every hole", RUNS),
        ("mujoco", "ros2"), "plant", "wall_stiffness", scale=1e3,
        left_out="each hole's own, 1 N/mm"),
    _physics("payload", NumberRange(float, 0.0, MAX_PAYLOAD_KG, unit="kg"), "KG",
             "mass at each EE the plant carries and the gravity compensation and the "
             "controllers do not know of", RUNS | {SWEEP}),
    _physics("coulomb_friction", NumberRange(float, 0.0, MAX_JOINT_FRICTION, unit="N m"), "NM",
             "dry friction of every joint"),
    _physics("viscous_friction", NumberRange(float, 0.0, MAX_JOINT_FRICTION,
                                             unit="N m s/rad"), "NMS",
             "viscous friction of every joint"),
    _physics("physics_rate", NumberRange(float, MIN_PHYSICS_RATE_HZ, MAX_PHYSICS_RATE_HZ,
                                         unit="Hz"), "HZ", "physics steps per second"),
    _physics("servo_bandwidth", NumberRange(float, 0.0, MAX_SERVO_BANDWIDTH_HZ,
                                            inclusive_minimum=False, unit="Hz"), "HZ",
             "natural frequency of each joint's position servo"),
    _physics("interface_limits", Choice(INTERFACE_MODES), None,
             "the robot's velocity interface checks each command's joint acceleration "
             "against the robot's limits (and the jerk against --interface-jerk-limit), 1%% "
             "tolerance: count counts the faults, strict stops the robot at the first, as a "
             "Franka's reflex does"),
    _physics("interface_jerk_limit", NumberRange(float, 0.0, MAX_INTERFACE_JERK,
                                                 inclusive_minimum=False, unit="rad/s^3"),
             "RAD_PER_S3", "the interface's jerk limit of every joint (with "
             "--interface-limits)", left_out="none"),
    _ros2("joint_states", Text(), "TOPIC", "the robot's sensor_msgs/JointState topic"),
    _ros2("command_topic", Text(), "TOPIC",
          "the JointGroupVelocityController's Float64MultiArray topic"),
    _ros2("command_joints", Names(), "NAMES",
          "the controller's 'joints' parameter, the commands' order",
          left_out="the robot model's joint order"),
    _ros2("crtk", Text(), "NAMESPACE", "a CRTK robot instead: NAMESPACE/measured_js, "
          "/servo_jv, /operating_state", left_out="ros2_control"),
    _ros2("ros_domain", NumberRange(int, 0, MAX_DOMAIN_ID), "N", "ROS 2 domain id",
          field="domain", left_out="ROS_DOMAIN_ID, else 0"),
    _ros2("realtime_priority", NumberRange(int, 0, MAX_PRIORITY), "N",
          "SCHED_FIFO priority of the threads on the wire, as ros2_control's "
          "controller_manager runs; 0: ordinary scheduling; without the privilege they stay "
          "ordinary and the measures say so",
          left_out="40, below the controller_manager's 50; teleop sim --ros2, which plays "
                   "the robot: 50"),
    PlantOption(SharedOption(
        "response_time", NumberRange(float, 0.0, MAX_RESPONSE_TIME_S, unit="s"), "S",
        "how late the robot follows a velocity command (its servos' time constant), what "
        "the collision damper counts on, as 1/(2 pi servo bandwidth) on the mujoco plant",
        RUNS), ("ros2",), "ros2", "response_time",
        left_out=f"{DEFAULT_RESPONSE_TIME:.4g}, a 20 Hz servo's"),
)

#: The plant options by name.
PLANT_OPTIONS_BY_NAME: dict[str, PlantOption] = {option.name: option
                                                  for option in PLANT_OPTIONS}


def holder_options(holder: str) -> tuple[PlantOption, ...]:
    """The options that set fields of ``holder`` (:data:`HOLDERS`)."""
    return tuple(option for option in PLANT_OPTIONS if option.holder == holder)
