"""ROS 2 messages as DDS types with ROS 2's names (docs/ros2.md, "Messages"): the few a
velocity-controlled or CRTK robot needs, declared as Cyclone DDS IDL structs whose type
names are the ones rosidl generates (``pkg::msg::dds_::Name_``), so that a ROS 2 node on
``rmw_cyclonedds_cpp`` matches them. Cyclone's Python binding does the CDR (no
hand-written serialisation); :mod:`teleop.plants.ros2.type_hashes` gives their RIHS01
hashes (rosbags) for the endpoints' user data.

:func:`ros_name` gives a type's ROS 2 name (``sensor_msgs/msg/JointState``)."""

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from cyclonedds.idl import IdlStruct

if TYPE_CHECKING:  # the Python types Cyclone's IDL annotations stand for
    float64 = float
    int32 = int
    uint32 = int
    sequence = list
else:
    from cyclonedds.idl.types import float64, int32, sequence, uint32


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    """``builtin_interfaces/msg/Time``: seconds and nanoseconds."""

    sec: int32 = 0
    nanosec: uint32 = 0

    @classmethod
    def of(cls, seconds: float) -> "Time":
        """The time ``seconds`` (since the epoch) as a ROS 2 stamp."""
        whole = int(seconds // 1)
        return cls(sec=whole, nanosec=int((seconds - whole) * 1e9))


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    """``std_msgs/msg/Header``: a stamp and a frame."""

    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class MultiArrayDimension(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayDimension_"):
    """``std_msgs/msg/MultiArrayDimension``."""

    label: str = ""
    size: uint32 = 0
    stride: uint32 = 0


@dataclass
class MultiArrayLayout(IdlStruct, typename="std_msgs::msg::dds_::MultiArrayLayout_"):
    """``std_msgs/msg/MultiArrayLayout``."""

    dim: sequence[MultiArrayDimension] = field(default_factory=list)
    data_offset: uint32 = 0


@dataclass
class Float64MultiArray(IdlStruct, typename="std_msgs::msg::dds_::Float64MultiArray_"):
    """``std_msgs/msg/Float64MultiArray``: what a ros2_control
    ``JointGroupVelocityController`` takes on ``/<controller>/commands`` (rad/s, m/s, in
    the controller's joint order)."""

    layout: MultiArrayLayout = field(default_factory=MultiArrayLayout)
    data: sequence[float64] = field(default_factory=list)


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    """``sensor_msgs/msg/JointState``: names with positions, velocities, efforts (each
    list empty or as long as ``name``)."""

    header: Header = field(default_factory=Header)
    name: sequence[str] = field(default_factory=list)
    position: sequence[float64] = field(default_factory=list)
    velocity: sequence[float64] = field(default_factory=list)
    effort: sequence[float64] = field(default_factory=list)


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    """``geometry_msgs/msg/Point`` (m)."""

    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    """``geometry_msgs/msg/Quaternion`` (x, y, z, w)."""

    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0
    w: float64 = 1.0


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    """``geometry_msgs/msg/Vector3``."""

    x: float64 = 0.0
    y: float64 = 0.0
    z: float64 = 0.0


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    """``geometry_msgs/msg/Pose``."""

    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class PoseStamped(IdlStruct, typename="geometry_msgs::msg::dds_::PoseStamped_"):
    """``geometry_msgs/msg/PoseStamped``: CRTK's ``measured_cp`` and ``servo_cp``."""

    header: Header = field(default_factory=Header)
    pose: Pose = field(default_factory=Pose)


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    """``geometry_msgs/msg/Twist``."""

    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class TwistStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TwistStamped_"):
    """``geometry_msgs/msg/TwistStamped``: CRTK's ``measured_cv``."""

    header: Header = field(default_factory=Header)
    twist: Twist = field(default_factory=Twist)


@dataclass
class Wrench(IdlStruct, typename="geometry_msgs::msg::dds_::Wrench_"):
    """``geometry_msgs/msg/Wrench``."""

    force: Vector3 = field(default_factory=Vector3)
    torque: Vector3 = field(default_factory=Vector3)


@dataclass
class WrenchStamped(IdlStruct, typename="geometry_msgs::msg::dds_::WrenchStamped_"):
    """``geometry_msgs/msg/WrenchStamped``: CRTK's ``servo_cf``, and the port force the
    simulated robot publishes."""

    header: Header = field(default_factory=Header)
    wrench: Wrench = field(default_factory=Wrench)


@dataclass
class OperatingState(IdlStruct, typename="crtk_msgs::msg::dds_::OperatingState_"):
    """``crtk_msgs/msg/OperatingState``: ``state`` is ``DISABLED``, ``ENABLED``,
    ``PAUSED`` or ``FAULT``; a CRTK robot takes ``servo_jv`` only when ``ENABLED`` and
    homed."""

    header: Header = field(default_factory=Header)
    state: str = ""
    is_homed: bool = False
    is_busy: bool = False


def ros_name(message_type: type) -> str:
    """The ROS 2 name of a type of this module: ``sensor_msgs::msg::dds_::JointState_``
    is ``sensor_msgs/msg/JointState``."""
    typename: str = getattr(message_type, "__idl_typename__", "")
    if typename.count("::") != 3 or not typename.endswith("_"):
        raise ValueError(f"{message_type.__name__} is not a ROS 2 message type")
    package, kind, _, name = typename.split("::")
    return f"{package}/{kind}/{name[:-1]}"


#: The ``crtk_msgs`` definition rosbags' stores lack (crtk_msgs/msg/OperatingState.msg).
OPERATING_STATE_DEFINITION = """std_msgs/Header header
string state
bool is_homed
bool is_busy
"""
