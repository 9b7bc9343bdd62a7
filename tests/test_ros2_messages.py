"""ROS 2's messages without ROS (teleop/plants/ros2, docs/ros2.md): the type hashes against
those a ROS 2 system reports, the CDR bytes against rosbags' own serialiser, the topic
names and the settings' refusals."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from teleop.plants.ros2.messages import (OPERATING_STATE_DEFINITION, Float64MultiArray, Header,
                                         JointState, OperatingState, Point, Pose, PoseStamped,
                                         Quaternion, Time, Vector3, Wrench, WrenchStamped,
                                         ros_name)
from teleop.plants.ros2.names import dds_topic, domain_id
from teleop.plants.ros2.node import endpoint_qos
from teleop.plants.ros2.settings import Ros2Settings
from teleop.plants.ros2.type_hashes import type_hash, user_data

#: RIHS01 hashes as ROS 2 Jazzy reports them (``ros2 topic info --verbose``, the
#: rosidl-generated type descriptions), written here, not computed.
KNOWN_HASHES = {
    "sensor_msgs/msg/JointState":
        "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
    "std_msgs/msg/Float64MultiArray":
        "RIHS01_1025ddc6b9552d191f89ef1a8d2f60f3d373e28b283d8891ddcc974e8c55397f",
    "std_msgs/msg/MultiArrayLayout":
        "RIHS01_4c66e6f78e740ac103a94cf63259f968e48c617e7699e829b63c21a5cb50dac6",
    "std_msgs/msg/MultiArrayDimension":
        "RIHS01_5e773a60a4c7fc8a54985f307c7837aa2994252a126c301957a24e31282c9cbe",
    "builtin_interfaces/msg/Time":
        "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197",
}


@pytest.mark.parametrize("name", sorted(KNOWN_HASHES))
def test_type_hash_is_ros2s(name: str) -> None:
    assert type_hash(name) == KNOWN_HASHES[name]


def test_user_data_carries_the_hash_as_rmw_cyclonedds_does() -> None:
    assert user_data("sensor_msgs/msg/JointState") == (
        b"typehash=" + KNOWN_HASHES["sensor_msgs/msg/JointState"].encode() + b";")
    with pytest.raises(ValueError, match="no_pkg/msg/Nothing"):
        type_hash("no_pkg/msg/Nothing")


def test_ros_names() -> None:
    assert ros_name(JointState) == "sensor_msgs/msg/JointState"
    assert ros_name(Float64MultiArray) == "std_msgs/msg/Float64MultiArray"
    assert ros_name(OperatingState) == "crtk_msgs/msg/OperatingState"
    with pytest.raises(ValueError, match="int"):
        ros_name(int)


STORE = get_typestore(Stores.ROS2_JAZZY)
STORE.register(get_types_from_msg(OPERATING_STATE_DEFINITION, "crtk_msgs/msg/OperatingState"))
T = STORE.types

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
names = st.text(st.characters(min_codepoint=33, max_codepoint=126), max_size=12)


def _header(sec: int, nanosec: int, frame: str):
    return (Header(stamp=Time(sec=sec, nanosec=nanosec), frame_id=frame),
            T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                     frame_id=frame))


stamps = st.tuples(st.integers(-2**31, 2**31 - 1), st.integers(0, 2**32 - 1), names)


@given(stamps, st.lists(st.tuples(names, finite, finite), max_size=8), st.booleans())
def test_joint_state_bytes_are_rosbags(stamp, joints, with_velocity: bool) -> None:
    ours_header, theirs_header = _header(*stamp)
    name = [j[0] for j in joints]
    position = [j[1] for j in joints]
    velocity = [j[2] for j in joints] if with_velocity else []
    ours = JointState(header=ours_header, name=name, position=position, velocity=velocity)
    theirs = T["sensor_msgs/msg/JointState"](
        header=theirs_header, name=name, position=np.array(position, dtype=float),
        velocity=np.array(velocity, dtype=float), effort=np.zeros(0))
    data = ours.serialize()
    assert data == bytes(STORE.serialize_cdr(theirs, "sensor_msgs/msg/JointState"))
    assert JointState.deserialize(data) == ours


@given(st.lists(finite, max_size=20))
def test_float64_multi_array_bytes_are_rosbags(values: list[float]) -> None:
    theirs = T["std_msgs/msg/Float64MultiArray"](
        layout=T["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0),
        data=np.array(values, dtype=float))
    assert Float64MultiArray(data=values).serialize() == bytes(
        STORE.serialize_cdr(theirs, "std_msgs/msg/Float64MultiArray"))


@given(stamps, st.lists(finite, min_size=7, max_size=7))
def test_pose_and_wrench_bytes_are_rosbags(stamp, v: list[float]) -> None:
    ours_header, theirs_header = _header(*stamp)
    pose = PoseStamped(header=ours_header, pose=Pose(position=Point(x=v[0], y=v[1], z=v[2]),
                                                     orientation=Quaternion(x=v[3], y=v[4],
                                                                            z=v[5], w=v[6])))
    theirs = T["geometry_msgs/msg/PoseStamped"](
        header=theirs_header, pose=T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=v[0], y=v[1], z=v[2]),
            orientation=T["geometry_msgs/msg/Quaternion"](x=v[3], y=v[4], z=v[5], w=v[6])))
    assert pose.serialize() == bytes(STORE.serialize_cdr(theirs, "geometry_msgs/msg/PoseStamped"))
    wrench = WrenchStamped(header=ours_header, wrench=Wrench(force=Vector3(x=v[0], y=v[1], z=v[2]),
                                                             torque=Vector3(x=v[3], y=v[4], z=v[5])))
    vector = T["geometry_msgs/msg/Vector3"]
    theirs_wrench = T["geometry_msgs/msg/WrenchStamped"](
        header=theirs_header, wrench=T["geometry_msgs/msg/Wrench"](
            force=vector(x=v[0], y=v[1], z=v[2]), torque=vector(x=v[3], y=v[4], z=v[5])))
    assert wrench.serialize() == bytes(
        STORE.serialize_cdr(theirs_wrench, "geometry_msgs/msg/WrenchStamped"))


@given(stamps, names, st.booleans(), st.booleans())
def test_operating_state_bytes_are_rosbags(stamp, state: str, homed: bool, busy: bool) -> None:
    ours_header, theirs_header = _header(*stamp)
    ours = OperatingState(header=ours_header, state=state, is_homed=homed, is_busy=busy)
    theirs = T["crtk_msgs/msg/OperatingState"](header=theirs_header, state=state,
                                               is_homed=homed, is_busy=busy)
    assert ours.serialize() == bytes(STORE.serialize_cdr(theirs, "crtk_msgs/msg/OperatingState"))


def test_topic_names_are_mangled_as_ros2_does() -> None:
    assert dds_topic("/joint_states") == "rt/joint_states"
    assert dds_topic("/forward_velocity_controller/commands") == \
        "rt/forward_velocity_controller/commands"
    assert dds_topic("PSM1/servo_jv") == "rt/PSM1/servo_jv"
    for bad in ("", "/", "/a//b", "/a/", "/a b"):
        with pytest.raises(ValueError, match="topic"):
            dds_topic(bad)


def test_domain_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "17")
    assert domain_id() == 17
    assert domain_id(3) == 3
    monkeypatch.delenv("ROS_DOMAIN_ID")
    assert domain_id() == 0
    for bad in (-1, 233, "x"):
        with pytest.raises(ValueError, match="ROS_DOMAIN_ID"):
            domain_id(bad)


def test_qos_is_ros2s_default() -> None:
    qos = endpoint_qos(JointState)
    text = str(qos)
    assert "Reliable" in text and "KeepLast(depth=10)" in text and "Volatile" in text
    assert KNOWN_HASHES["sensor_msgs/msg/JointState"] in text


def test_settings_refusals_name_the_field() -> None:
    with pytest.raises(ValueError, match="stale_after"):
        Ros2Settings(stale_after=0.0)
    with pytest.raises(ValueError, match="start_timeout"):
        Ros2Settings(start_timeout=float("nan"))
    with pytest.raises(ValueError, match="twice"):
        Ros2Settings(command_joints=("a", "a"))
    with pytest.raises(ValueError, match="topic"):
        Ros2Settings(joint_states="/a//b")
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID"):
        Ros2Settings(domain=500)
    settings = Ros2Settings(command_joints=("b", "a"), crtk="/PSM1", domain=4)
    assert Ros2Settings.from_dict(settings.to_dict()) == settings
    assert settings.state_topic == "/PSM1/measured_js"
    assert settings.commands == "/PSM1/servo_jv"
    with pytest.raises(ValueError, match="unknown"):
        Ros2Settings.from_dict({"topic": 1})


@pytest.mark.parametrize("argv, message", [
    (["sim", "--ros2", "--q0", "1,2"], "teleop sim: --q0 needs 8 finite numbers, got 2"),
    (["sim", "--ros2", "--ros-domain", "999"],
     "argument --ros-domain: must be in [0, 232], got 999"),
    (["sim", "--ros2", "--command-joints", "a,b"], "does not carry the joints"),
    (["compare", "--scenario", "paper-hole", "--crtk", "/PSM1"], "--crtk needs --plant ros2"),
])
def test_bad_ros2_options_are_one_line(argv: list[str], message: str,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    from teleop.cli.main import main

    try:
        code = main(argv)
    except SystemExit as stop:  # argparse's own refusal (the option's declared range)
        code = stop.code
    assert code == 2
    error = capsys.readouterr().err
    assert message in error and error.count("\n") == 1


def test_compare_runs_one_controller_on_a_ros2_robot() -> None:
    from teleop.experiments.compare import compare
    from teleop.experiments.scenarios import load_scenario
    from teleop.plants.choice import PlantChoice

    with pytest.raises(ValueError, match="one robot: run one controller on it .* got 2: cjm, qp"):
        compare(load_scenario("trocar-circle"), ["cjm", "qp"], plant=PlantChoice("ros2"))


def test_the_bench_refuses_a_ros2_robot() -> None:
    from teleop.experiments.bench import run_bench
    from teleop.plants.choice import PlantChoice

    with pytest.raises(ValueError, match="not on a ROS 2 robot"):
        run_bench(["ur5_instrument"], ["cjm"], iterations=5, plant=PlantChoice("ros2"))
