"""Every controller in the closed loop on the MuJoCo plant, under random operator jumps, an
unmodelled payload and a hole that may sit off the instrument: every command is finite and
inside the joint box of the configuration it was computed for (velocity, braking-aware
position and acceleration limits around the previous command), and a step that did not
hold its hole rows never says ``ok`` (docs/design.md sections 8, 17)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from constraints import Hole
from controllers.base import EQUALITY_TOLERANCE
from teleop import load_robot
from teleop.controller_specs import ROBOT, make_controller
from teleop.loop import LoopConfig, TeleopLoop
from teleop.plants import MujocoPlant, PlantSettings

SPECS = ("cjm", "cjm:python", "cjm:general", "qp:proxqp", "qp:daqp", "qp:osqp", "mink:daqp")
ROBOTS = ("sda10f", "ur5_instrument", "sda10f_dual")
TICKS = 150


@pytest.fixture(scope="module")
def robots():
    return {name: load_robot(name) for name in ROBOTS}


@st.composite
def runs(draw):
    return (draw(st.sampled_from(ROBOTS)), draw(st.sampled_from(SPECS)),
            draw(st.floats(0.0, 1.0)),  # payload (kg)
            draw(st.floats(-0.01, 0.01)),  # the hole's centre off the instrument (m)
            draw(st.integers(0, 2 ** 31 - 1)))  # the operator's jumps


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(run=runs())
def test_every_controller_on_the_plant_is_finite_in_its_box_and_honest(robots, run):
    name, spec, payload, off_axis, seed = run
    robot = robots[name]
    rng = np.random.default_rng(seed)
    config = LoopConfig()
    q0 = robot.q_home.copy()
    holes = [Hole.on_link(robot, q0, distance=0.05, link=link) for link in robot.constrained_links]
    holes[0].center = holes[0].center + np.array([off_axis, 0.0, 0.0])
    controller = make_controller(spec, robot, holes, dt=config.dt, time_budget=None,
                                 acceleration_limit=ROBOT)
    plant = MujocoPlant(robot, config.dt, PlantSettings(payload=payload))
    loop = TeleopLoop(robot, controller, q0=q0, config=config, plant=plant)
    targets = loop.ee_placements()
    velocity_limit = controller.joint_bounds.velocity_limit
    slack = 1e-9 * np.where(np.isfinite(velocity_limit), velocity_limit, 1.0)
    acceleration_step = controller.joint_bounds.acceleration_step
    assert acceleration_step is not None and np.all(np.isfinite(acceleration_step))
    previous = np.zeros(robot.model.nv)  # at rest
    for tick in range(TICKS):
        if tick % 50 == 0:  # the operator jumps: up to 5 cm and 0.3 rad per EE
            targets = [pose * pin.exp6(np.concatenate([rng.uniform(-0.05, 0.05, 3),
                                                      rng.uniform(-0.3, 0.3, 3)]))
                       for pose in targets]
        step = loop.advance(targets)
        loop.measure_command(step)
        record = loop.measure(step)
        assert np.all(np.isfinite(step.qd)), (spec, step.message)
        assert np.all(np.isfinite(loop.q)) and record.plant is not None
        assert np.all(np.isfinite(record.plant.port_forces))
        # the box of the sensed configuration around the previous command: velocity,
        # braking-aware position and acceleration limits (a failed step's stop too)
        lower, upper = controller.joint_bounds.box(step.sensed, previous)
        assert np.all(step.qd >= lower - slack) and np.all(step.qd <= upper + slack), \
            (spec, tick, step.status, step.message)
        change = np.abs(step.qd - previous)
        inside_position_box = np.all(previous >= lower - slack) & np.all(previous <= upper + slack)
        if inside_position_box:  # the acceleration limit gives way only to position limits
            assert np.all(change <= acceleration_step * (1 + 1e-9) + slack), (spec, tick)
        previous = step.qd.copy()
        if step.status == "ok":  # the hole rows held at the sensed configuration
            assert record.constraint_velocity_residual <= 1e3 * EQUALITY_TOLERANCE, \
                (spec, tick, record.constraint_velocity_residual)
