"""A physics plant that is not kinder than a robot (docs/design.md section 17.1, issue 32
item 5): the command latency shifts the response by whole periods, the interface refuses
a command beyond the robot's acceleration or jerk limits and stops the robot, a URDF's
rotor inertias become MuJoCo's armature, and the wall's force splits into its spring and
damper parts."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from teleop.plants import Imperfections, MujocoPlant, PlantSettings
from teleop.plants.armature import urdf_armatures
from teleop.plants.interface import INTERFACE_TOLERANCE, CommandInterface
from teleop.robots.robot import load_robot
from teleop.plants.walls import PortWall

from test_mujoco_plant import _hole_through_link

DT = 1e-3
#: the wall the plant puts at a hole
WALL = PortWall()
JOINT = 2  # the velocity coordinate the scripted commands move


def _ramp(limit: float, jump_at: int, steps: int, factor: float) -> list[np.ndarray]:
    """Joint ``JOINT`` accelerating at half its limit, then at ``jump_at`` one command
    whose acceleration is ``factor`` times the limit, then holding that velocity."""
    commands, velocity = [], 0.0
    for k in range(steps):
        velocity += (factor if k == jump_at else 0.5 if k < jump_at else 0.0) * limit * DT
        command = np.zeros(8)
        command[JOINT] = velocity
        commands.append(command)
    return commands


def _run(plant: MujocoPlant, robot, commands) -> tuple[np.ndarray, list]:
    """Each period's mean velocity and the plant's measures, the loop's integration."""
    q, velocities, measures = robot.q_home.copy(), [], []
    for qd in commands:
        v = plant.actuate(qd, q)
        q = pin.integrate(robot.model, q, v * DT)
        velocities.append(v)
        measures.append(plant.measures())
    return np.array(velocities), measures


@pytest.mark.parametrize("latency", [0, 3])
def test_strict_interface_refuses_the_one_command_beyond_the_limit_and_stops(sda10f,
                                                                            latency):
    limit = sda10f.acceleration_limit[JOINT]
    commands = _ramp(limit, jump_at=40, steps=200, factor=3.0)
    plant = MujocoPlant(sda10f, DT, PlantSettings(interface_limits="strict", gravity=False),
                        Imperfections(latency=latency))
    velocities, measures = _run(plant, sda10f, commands)
    faults = [i for i, m in enumerate(measures) if m.interface_fault is not None]
    assert faults == [40 + latency]  # exactly one, when the command reaches the robot
    fault = measures[40 + latency].interface_fault
    assert fault.period == 40 + latency and fault.quantity == "acceleration"
    assert fault.joint == sda10f.model.names[1 + JOINT]  # one dof per joint on sda10f
    assert fault.value == pytest.approx(3.0 * limit) and fault.limit == limit
    assert plant.interface.faults == 1 and plant.interface.stopped
    assert [m.interface_stopped for m in measures] == [i >= 40 + latency for i in range(200)]
    # the robot stops: from moving at 20 x the limit x dt to rest within 0.15 s
    moving = abs(velocities[40 + latency - 1, JOINT])
    assert moving > 0.25
    assert np.max(np.abs(velocities[-10:])) < 1e-3 * moving


def test_within_the_limit_nothing_is_refused_and_count_mode_does_not_stop(sda10f):
    limit = sda10f.acceleration_limit[JOINT]
    inside = _ramp(limit, jump_at=40, steps=100, factor=1.0 + 0.5 * INTERFACE_TOLERANCE)
    plant = MujocoPlant(sda10f, DT, PlantSettings(interface_limits="strict", gravity=False))
    _, measures = _run(plant, sda10f, inside)
    assert plant.interface.faults == 0 and not plant.interface.stopped
    # count: two jumps beyond the limit are counted, every command executed
    twice = _ramp(limit, jump_at=40, steps=100, factor=2.0)
    twice[70:] = [2.0 * c for c in twice[70:]]  # a second jump, of the held velocity
    counting = MujocoPlant(sda10f, DT, PlantSettings(interface_limits="count", gravity=False))
    reference = MujocoPlant(sda10f, DT, PlantSettings(gravity=False))
    counted, measures = _run(counting, sda10f, twice)
    unchecked, _ = _run(reference, sda10f, twice)
    assert [i for i, m in enumerate(measures) if m.interface_fault] == [40, 70]
    assert counting.interface.faults == 2 and not counting.interface.stopped
    np.testing.assert_array_equal(counted, unchecked)  # a monitor only


def test_the_jerk_limit_refuses_an_acceleration_step():
    """Acceleration 10 rad/s^2 reached in one period: jerk 1e4 rad/s^3, beyond 5e3."""
    model = load_robot("sda10f").model
    interface = CommandInterface("strict", model, DT, None, jerk_limit=5e3)
    velocity = np.zeros(8)
    velocity[JOINT] = 10.0 * DT
    accepted, fault = interface.receive(velocity)
    assert fault is not None and fault.quantity == "jerk"
    assert fault.value == pytest.approx(1e4) and not accepted.any()
    smooth = CommandInterface("strict", model, DT, None, jerk_limit=5e3)
    for k in range(1, 5):  # the same acceleration reached at 2.5e3 rad/s^3
        velocity[JOINT] = sum(min(i, 4) * 2.5 for i in range(1, k + 1)) * DT
        assert smooth.receive(velocity.copy())[1] is None


def test_the_latency_shifts_the_plant_response_by_exactly_its_periods(sda10f):
    commands = [np.sin(0.02 * k) * np.linspace(0.05, 0.2, 8) for k in range(150)]
    responses = {}
    for latency in (0, 4):
        plant = MujocoPlant(sda10f, DT, PlantSettings(gravity=False),
                            Imperfections(latency=latency))
        responses[latency], _ = _run(plant, sda10f, commands)
    np.testing.assert_array_equal(responses[4][:4], 0.0)
    np.testing.assert_allclose(responses[4][4:], responses[0][:-4], rtol=0, atol=1e-12)


def test_bad_interface_settings_are_refused_naming_the_field(sda10f):
    with pytest.raises(ValueError, match="interface_limits"):
        PlantSettings(interface_limits="on")
    with pytest.raises(ValueError, match="interface_jerk_limit"):
        PlantSettings(interface_limits="strict", interface_jerk_limit=-1.0)
    with pytest.raises(ValueError, match="interface_jerk_limit needs interface_limits"):
        PlantSettings(interface_jerk_limit=5e3)
    with pytest.raises(ValueError, match="interface_limits strict needs"):
        CommandInterface("strict", sda10f.model, DT, None, None)
    settings = PlantSettings(interface_limits="count", interface_jerk_limit=5e3)
    assert PlantSettings.from_dict(settings.to_dict()) == settings


def test_the_spring_part_is_k_times_the_displacement_and_the_rest_the_damper(sda10f):
    """Moving across a displaced port: at the last physics step, the spring part equals
    ``-k (P - c)`` and the damper part ``-c_d v_perp`` computed with Pinocchio at that
    step's configuration and velocity (independent of the plant's MuJoCo kinematics)."""
    q = sda10f.q_home.copy()
    hole, _ = _hole_through_link(sda10f, q, 2e-3)
    plant = MujocoPlant(sda10f, DT, PlantSettings(gravity=False))
    command = np.zeros(8)
    command[[1, 3]] = 0.3, -0.2
    for _ in range(30):
        q = pin.integrate(sda10f.model, q, plant.actuate(command, q, [hole]) * DT)
    m = plant.measures()
    assert np.linalg.norm(m.port_spring_forces[0]) == pytest.approx(
        hole.tissue_stiffness * m.port_displacements[0], rel=1e-12)
    # the last step again, the parts from Pinocchio
    mujoco.mj_step1(plant.mj_model, plant.mj_data)
    force, spring, _ = plant._push(hole, WALL)
    model, data = sda10f.model, sda10f.model.createData()
    q_mj, v_mj = plant.mj_data.qpos.copy(), plant.mj_data.qvel.copy()
    frame = model.getFrameId(hole.link)
    pin.forwardKinematics(model, data, q_mj, v_mj)
    pin.updateFramePlacements(model, data)
    placement = data.oMf[frame]
    point, axis = WALL.port(hole, placement.rotation, placement.translation)
    twist = pin.getFrameVelocity(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
    velocity = twist.linear + np.cross(twist.angular, point - placement.translation)
    lateral = velocity - (axis @ velocity) * axis
    np.testing.assert_allclose(spring, -hole.tissue_stiffness * (point - hole.center),
                               atol=1e-12)
    np.testing.assert_allclose(force - spring, -hole.tissue_damping * lateral, atol=1e-12)
    assert np.linalg.norm(force - spring) > 1e-3  # the damper is working here


def test_a_urdf_rotor_inertia_becomes_the_joint_armature(sda10f, tmp_path):
    """Drake's tags on one joint: ``N^2 I_r`` there, the setting on the others."""
    urdf = sda10f.urdf_path.read_text()
    joint = sda10f.model.names[2]
    transmission = (f'<transmission name="t"><joint name="{joint}"/><actuator name="m">'
                    '<drake:rotor_inertia value="2e-5"/><drake:gear_ratio value="120"/>'
                    '</actuator></transmission></robot>')
    path = tmp_path / "sda10f_rotor.urdf"
    urdf = urdf.replace("<robot ", '<robot xmlns:drake="http://drake.mit.edu" ', 1)
    path.write_text(urdf.replace("</robot>", transmission))
    assert urdf_armatures(path.read_text()) == {joint: pytest.approx(120 ** 2 * 2e-5)}
    robot = load_robot(path, ee_frames=list(sda10f.ee_frames))
    plant = MujocoPlant(robot, DT, PlantSettings(armature=0.05))
    dof = plant.mj_model.jnt_dofadr[plant.mj_model.joint(joint).id]
    expected = np.full(plant.mj_model.nv, 0.05)
    expected[dof] = 120 ** 2 * 2e-5
    np.testing.assert_allclose(plant.mj_model.dof_armature, expected)
    with pytest.raises(ValueError, match="rotor_inertia value"):
        urdf_armatures(path.read_text().replace('"2e-5"', '"-1"'), "here")
