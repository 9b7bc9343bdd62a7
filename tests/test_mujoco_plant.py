"""The MuJoCo physics plant (docs/design.md section 17): the servos hold and track, the
abdominal wall pushes back with the hole's spring-damper, the payload sags as statics
predict, and bad settings are refused."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from constraints import Hole
from example_robots import EXAMPLE_ARMS
from teleop.plants import Imperfections, MujocoPlant, PlantSettings
from teleop.plants.walls import PortWall

DT = 1e-3
#: the wall the plant puts at a hole
WALL = PortWall()


def run(plant: MujocoPlant, robot, q: np.ndarray, commands, holes=()) -> np.ndarray:
    """The loop's integration of the plant's mean velocities, one period per command."""
    for qd in commands:
        q = pin.integrate(robot.model, q, plant.actuate(qd, q, holes) * DT)
    return q


@pytest.mark.parametrize("name", ["sda10f", "ur5_instrument", "dual", "mobile"])
def test_with_zero_command_the_gravity_compensated_robot_holds_still(name, request):
    robot = request.getfixturevalue(name)
    plant = MujocoPlant(robot, DT)
    assert plant.substeps >= 2 and plant.mj_model.opt.timestep <= 0.5e-3 + 1e-15
    assert np.linalg.norm(plant.mj_model.opt.gravity) == pytest.approx(9.81)
    zero = np.zeros(robot.model.nv)
    q = run(plant, robot, robot.q_home.copy(), [zero] * 5000)  # 5 s
    drift = np.max(np.abs(pin.difference(robot.model, robot.q_home, q)))
    assert drift <= 1e-4, drift
    # the drives hold the robot's weight: a real torque, inside the URDF's effort limits
    assert 0.05 < plant.measures().torque_ratio < 1.0 and not plant.measures().saturated


@pytest.mark.parametrize("name", ["panda", "ur5", "xarm7", "kinova"])
def test_any_urdf_holds_still_on_the_plant(name):
    """Robots nobody here wrote (example-robot-data), the Panda's fingers locked, Kinova's
    continuous joints ((cos, sin) in Pinocchio, an angle in MuJoCo)."""
    locked = {"locked_joints": ["panda_finger_joint1", "panda_finger_joint2"]} if name == "panda" else {}
    robot = EXAMPLE_ARMS[name].load(**locked)
    plant = MujocoPlant(robot, DT)
    q = run(plant, robot, robot.q_home.copy(), [np.zeros(robot.model.nv)] * 2000)
    assert np.max(np.abs(pin.difference(robot.model, robot.q_home, q))) <= 1e-4
    assert 0.05 < plant.measures().torque_ratio < 1.0


def test_without_the_drives_compensation_the_robot_falls(sda10f):
    """The hold above is the servos' doing: with the compensation's own gravity only (no
    drive torque, the same model) the arm moves off by far more than the hold's bound."""
    plant = MujocoPlant(sda10f, DT)
    plant.mj_model.actuator_gainprm[:] = 0.0
    plant.mj_model.actuator_biasprm[:] = 0.0
    plant.mj_model.jnt_actgravcomp[:] = 0  # gravity compensation off with the drives
    plant.mj_model.body_gravcomp[:] = 0.0
    q = run(plant, sda10f, sda10f.q_home.copy(), [np.zeros(8)] * 200)
    assert np.max(np.abs(q - sda10f.q_home)) > 1e-2


def test_a_slow_motion_stays_within_the_servo_bound_of_the_kinematic_plant(sda10f):
    """A smooth joint-velocity profile ``v(t) = A sin(w t)``: the servo's tracking error
    is about the inertial lag ``|a| / omega_servo^2`` (velocity feed-forward cancels the
    rest); bound it at 10x that (coupling between joints, damping not fed forward)."""
    plant = MujocoPlant(sda10f, DT)
    amplitude, frequency = 0.3, 2 * math.pi * 0.5
    times = np.arange(2000) * DT
    commands = [amplitude * math.sin(frequency * t) * np.ones(8) for t in times]
    q_plant, q_kinematic, worst = sda10f.q_home.copy(), sda10f.q_home.copy(), 0.0
    for qd in commands:
        q_plant = pin.integrate(sda10f.model, q_plant, plant.actuate(qd, q_plant) * DT)
        q_kinematic = pin.integrate(sda10f.model, q_kinematic, qd * DT)
        worst = max(worst, float(np.max(np.abs(q_plant - q_kinematic))))
    omega = 2 * math.pi * plant.settings.servo_bandwidth
    lag = amplitude * frequency / omega ** 2 + plant.settings.joint_damping * amplitude / \
        np.min(plant.kp)  # inertial lag, plus the unmodelled damping's torque over kp
    assert 1e-7 < worst < 10 * lag, (worst, lag)


def _hole_through_link(robot, q, lateral: float, plant_kinematics=True) -> tuple[Hole, np.ndarray]:
    """A hole 0.1 m along the instrument, its centre moved ``lateral`` m across the axis;
    the unit direction of that move."""
    hole = Hole.on_link(robot, q, distance=0.1)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    axis = data.oMf[robot.model.getFrameId(hole.link)].rotation @ hole.link_axis
    across = np.cross(axis, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    hole.center = hole.center + lateral * across
    return hole, across


@pytest.mark.parametrize("lateral", [0.0, 1e-3, 4e-3])
def test_the_port_force_is_the_stiffness_times_the_lateral_offset(sda10f, lateral):
    q = sda10f.q_home.copy()
    hole, across = _hole_through_link(sda10f, q, lateral)
    plant = MujocoPlant(sda10f, DT)
    plant.actuate(np.zeros(8), q, [hole])
    force = plant.measures().port_forces[0]
    if lateral == 0.0:
        assert np.linalg.norm(force) < 1e-9
        return
    # the instrument is pulled toward the centre: +across, k * offset, within 1 %
    # (it has moved by a fraction of a micrometre in the half millisecond before)
    expected = hole.tissue_stiffness * lateral * across
    assert np.linalg.norm(force - expected) <= 0.01 * np.linalg.norm(expected)
    assert plant.measures().port_displacements[0] == pytest.approx(lateral, rel=0.01)


def test_the_torque_ratio_is_the_largest_drive_torque_over_its_effort_limit(sda10f):
    """Every period, slow to saturating commands with a port: the measured ratio and the
    saturation equal numpy's ``max |qfrc_actuator| / actfrcrange`` of the MjData, read
    from MuJoCo's model here, bit for bit; no contact in a scene without geometry."""
    q = sda10f.q_home.copy()
    hole, _ = _hole_through_link(sda10f, q, 1e-3)
    plant = MujocoPlant(sda10f, DT)
    model = plant.mj_model
    limits = np.full(model.nv, np.inf)
    limited = model.jnt_actfrclimited.astype(bool)
    limits[model.jnt_dofadr[limited]] = model.jnt_actfrcrange[limited, 1]
    ratios = []
    for size in [0.0, 0.1, 1.0, 3.0, 10.0, 30.0]:
        for _ in range(20):
            qd = np.full(8, size) * np.array([1, -1] * 4)
            q = pin.integrate(sda10f.model, q, plant.actuate(qd, q, [hole]) * DT)
            expected = float(np.max(np.abs(plant.mj_data.qfrc_actuator) / limits))
            measures = plant.measures()
            assert measures.torque_ratio == expected
            assert measures.saturated == (expected >= 1.0 - 1e-12)
            assert measures.contacts == 0 and measures.contact_depth == 0.0
            ratios.append(expected)
    assert min(ratios) < 0.5 and max(ratios) >= 1.0 - 1e-12  # held and saturated both seen


def test_the_wall_force_reaches_the_joints_as_the_point_jacobian_transpose(sda10f):
    """The generalized force MuJoCo applies equals Pinocchio's ``J_P^T F`` at the port
    point (an independent Jacobian), and the instrument then moves toward the centre."""
    q = sda10f.q_home.copy()
    hole, across = _hole_through_link(sda10f, q, 2e-3)
    plant = MujocoPlant(sda10f, DT)
    plant.actuate(np.zeros(8), q, [hole])
    force = plant.measures().port_forces[0]
    q_mj = plant.mj_data.qpos.copy()  # the identity map on a fixed-base robot
    model, data = sda10f.model, sda10f.model.createData()
    frame = model.getFrameId(hole.link)
    # the applied force of the last physics step, at the configuration it was computed at
    mujoco.mj_step1(plant.mj_model, plant.mj_data)
    plant.mj_data.qfrc_applied[:] = 0.0
    plant._push(hole, WALL)
    pin.computeJointJacobians(model, data, q_mj)
    pin.updateFramePlacements(model, data)
    placement = data.oMf[frame]
    point, _ = WALL.port(hole, placement.rotation, placement.translation)
    jacobian = pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
    linear = jacobian[:3] - pin.skew(point - placement.translation) @ jacobian[3:]
    force = plant.mj_data.qfrc_applied.copy()
    expected = linear.T @ WALL.force(hole, point, WALL.port(hole, placement.rotation,
                                                            placement.translation)[1],
                                          linear @ plant.mj_data.qvel)
    np.testing.assert_allclose(force, expected, atol=1e-9 * np.max(np.abs(expected)))
    # a compliant servo lets the wall move the instrument toward the centre
    soft = MujocoPlant(sda10f, DT, PlantSettings(servo_bandwidth=1.0))
    start = WALL.port(hole, placement.rotation, placement.translation)[0]
    q_after = run(soft, sda10f, q, [np.zeros(8)] * 300, [hole])
    pin.framesForwardKinematics(model, data, q_after)
    moved = WALL.port(hole, data.oMf[frame].rotation, data.oMf[frame].translation)[0] - start
    assert moved @ across > 1e-5


def test_an_unmodelled_payload_sags_as_statics_predict(sda10f):
    """At rest with a payload ``m`` at the tool, each servo's spring holds its share of the
    payload's weight: ``kp (q_ref - q) = -J^T (0, 0, -m g)``, so ``q - q_ref = J^T m g / kp``
    with Pinocchio's EE Jacobian (the damping has settled after 2 s)."""
    mass = 0.5
    plant = MujocoPlant(sda10f, DT, PlantSettings(payload=mass))
    q = run(plant, sda10f, sda10f.q_home.copy(), [np.zeros(8)] * 2000)
    model, data = sda10f.model, sda10f.model.createData()
    jacobian = pin.computeFrameJacobian(model, data, q, sda10f.ee_frame_id, pin.LOCAL_WORLD_ALIGNED)
    torque = jacobian[:3].T @ np.array([0.0, 0.0, -mass * 9.81])
    expected = torque / plant.kp
    sag = q - sda10f.q_home
    assert np.max(np.abs(expected)) > 1e-5
    np.testing.assert_allclose(sag, expected, atol=0.05 * np.max(np.abs(expected)))


def test_the_mobile_base_follows_its_velocity_command(mobile):
    """Base velocities in the base frame (Pinocchio's planar joint): the simulated base
    ends where the kinematic integration does, within the servos' lag."""
    plant = MujocoPlant(mobile, DT)
    qd = np.zeros(mobile.model.nv)
    qd[:3] = 0.1, -0.05, 0.2
    ramp = [qd * min(1.0, k / 300) for k in range(1500)]
    q_plant, q_kinematic = mobile.q_home.copy(), mobile.q_home.copy()
    for command in ramp:
        q_plant = pin.integrate(mobile.model, q_plant, plant.actuate(command, q_plant) * DT)
        q_kinematic = pin.integrate(mobile.model, q_kinematic, command * DT)
    travelled = np.linalg.norm(q_kinematic[:2] - mobile.q_home[:2])
    assert travelled > 0.08
    assert np.max(np.abs(pin.difference(mobile.model, q_plant, q_kinematic))) < 2e-3


def test_encoder_noise_is_on_top_of_the_simulated_configuration(sda10f):
    plant = MujocoPlant(sda10f, DT, imperfections=Imperfections(encoder_noise=1e-3, seed=3))
    sensed = np.array([plant.sense(sda10f.q_home) - sda10f.q_home for _ in range(400)])
    assert np.std(sensed) == pytest.approx(1e-3, rel=0.15)


@settings(max_examples=25, deadline=None)
@given(field=st.sampled_from(["physics_rate", "servo_bandwidth", "servo_damping_ratio",
                              "armature", "joint_damping", "payload", "coulomb_friction",
                              "viscous_friction"]),
       value=st.sampled_from([-1.0, float("nan"), float("inf"), "1", None, 1e9]))
def test_bad_settings_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        PlantSettings(**{field: value})


def test_the_physics_runs_at_least_twice_the_control_rate():
    assert PlantSettings().substeps(1e-3) == 2
    assert PlantSettings(physics_rate=5000.0).substeps(1e-3) == 5
    assert PlantSettings().substeps(0.25e-3) == 2  # a 4 kHz loop still gets two steps
    with pytest.raises(ValueError, match="physics_rate"):
        PlantSettings(physics_rate=1000.0)


def test_the_slow_paper_scenario_on_the_plant_follows_the_ideal_integrator(sda10f):
    """The paper's slow operator motion (+-1.5 cm) with the CJM: on the stiff plant the EE
    stays within 20 um of its path on the ideal integrator (the servos' lag, `a / w^2`,
    times the arm's reach, is a few microns) and the hole error within 1 um."""
    from teleop.controller_specs import make_controller
    from teleop.experiments.scenarios import load_scenario
    from teleop.loop import LoopConfig, TeleopLoop

    plan, config = load_scenario("paper-hole", sda10f), LoopConfig()
    paths, hole_errors = {}, {}
    for name in ("kinematic", "mujoco"):
        constraints = plan.make_constraints()
        controller = make_controller("cjm", sda10f, constraints, dt=config.dt)
        plant = MujocoPlant(sda10f, config.dt) if name == "mujoco" else None
        loop = TeleopLoop(sda10f, controller, q0=plan.q0, config=config, plant=plant)
        path, worst = [], 0.0
        for i in range(1500):
            record = loop.tick(plan.target((i + 1) * config.dt))
            path.append(loop.ee_placement().translation.copy())
            worst = max(worst, record.constraint_error)
            assert not record.failed, record.message
        paths[name], hole_errors[name] = np.array(path), worst
    apart = np.max(np.linalg.norm(paths["mujoco"] - paths["kinematic"], axis=1))
    assert 1e-8 < apart < 20e-6, apart
    assert hole_errors["mujoco"] < 1e-6, hole_errors


@settings(max_examples=25, deadline=None)
@given(payload=st.floats(0.0, 100.0), friction=st.floats(0.0, 1e4),
       bandwidth=st.floats(0.1, 200.0), gravity=st.booleans())
def test_plant_settings_round_trip_through_their_dict(payload, friction, bandwidth, gravity):
    chosen = PlantSettings(payload=payload, coulomb_friction=friction,
                           servo_bandwidth=bandwidth, gravity=gravity)
    data = chosen.to_dict()
    assert data["payload_kg"] == payload and data["servo_bandwidth_hz"] == bandwidth
    assert PlantSettings.from_dict(data) == chosen
    assert set(chosen.changed()) <= set(data)
    assert ("payload_kg" in chosen.changed()) == (payload != 0.0)
