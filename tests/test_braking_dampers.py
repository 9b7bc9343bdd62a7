"""The braking-aware velocity dampers of the barriers and the collision pairs with
acceleration limits (docs/design.md sections 12 and 18.3).

* The damper's allowed approach speed against a brute-force simulation of braking written
  here: the largest speed from which the point still stops before the plane, slowing by
  ``a_n dt`` a period, every period covering at most ``K dt`` of the gap left.
* Every controller on the ideal integrator: the mobile base approaching a wall at its top
  speed, from any distance, never crosses it; without acceleration limits the bound is
  the plain damper's.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from constraints import Barrier
from controllers.joint_acceleration import DAMPER_BRAKING_SHARE, braked_lower
from teleop import load_robot
from teleop.controller_specs import ROBOT, make_controller

SPECS = ("cjm", "cjm:python", "cjm:general", "qp:proxqp", "qp:daqp", "mink:daqp", "mink:proxqp")


def stops_before_the_plane(speed: float, gap: float, deceleration: float, dt: float,
                           gain: float) -> bool:
    """Brute force: approach at ``speed`` now, then slow by ``deceleration dt`` a period to
    a stop; each period the damper allows covering at most ``gain dt`` of the gap left."""
    left = gap
    while speed > 0.0:
        if speed * dt > gain * dt * left * (1.0 + 1e-12):
            return False
        left -= speed * dt
        speed -= deceleration * dt
    return left >= 0.0


@settings(max_examples=300, deadline=None)
@given(gap=st.floats(0.0, 1.0), gain=st.floats(1.0, 900.0), acceleration=st.floats(0.1, 50.0),
       row=st.floats(0.05, 2.0), dt=st.sampled_from([1e-3, 2e-3, 1e-2 / 9.0]))
def test_the_damper_allows_the_largest_approach_that_still_stops(gap, gain, acceleration, row,
                                                                  dt):
    """One joint moving the point along the normal at ``row`` m per unit: the deceleration
    counted on is ``DAMPER_BRAKING_SHARE row a``; the allowed approach ``f - lower`` is at
    most ``K g``, stops in time, and 1e-6 faster does not."""
    if gain * dt >= 1.0:
        gain = 0.9 / dt
    lower = np.array([-gain * gap])
    braked = braked_lower(np.array([[row]]), lower, np.array([gap]), np.array([gain]),
                          np.array([acceleration]), dt)
    approach = -float(braked[0])
    deceleration = DAMPER_BRAKING_SHARE * row * acceleration
    assert -1e-12 <= approach <= gain * gap * (1.0 + 1e-12) + 1e-15
    assert stops_before_the_plane(approach * (1.0 - 1e-9), gap, deceleration, dt, gain)
    faster = approach * (1.0 + 1e-6) + 1e-9 * deceleration * dt
    assert not stops_before_the_plane(faster, gap, deceleration, dt, gain)


def test_without_acceleration_limits_the_bound_is_the_plain_dampers():
    lower = np.array([-0.3])
    assert braked_lower(np.ones((1, 2)), lower, np.array([0.01]), np.array([30.0]), None,
                        1e-3) is lower


@pytest.fixture(scope="module")
def mobile():
    return load_robot("sda10f_dual_mobile")


#: the control period and the barrier gain of the closed-loop test (K dt = 0.2)
DT, GAIN = 2e-3, 100.0


def front_barrier(robot, q: np.ndarray, gap: float) -> Barrier:
    """A wall ``gap`` m ahead of the middle of the base's front edge (mobile-wall's wall)."""
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    base = data.oMf[model.getFrameId("mobile_base")]
    wall = base.act(np.array([0.4 + gap, 0.0, 0.0]))
    facing = base.rotation @ np.array([-1.0, 0.0, 0.0])
    return Barrier("mobile_base", [0.4, 0.0, 0.0], wall, facing, gain=GAIN)


def top_speed(controller, barrier: Barrier, q: np.ndarray) -> float:
    """The fastest forward base speed the braking-aware damper allows at ``q``, at most the
    base's velocity limit."""
    model = controller.model
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    frame = model.getFrameId(barrier.link)
    rows, rhs = barrier.rows(model, data, frame)
    braked = braked_lower(rows, rhs, barrier.error(data.oMf[frame]), np.array([barrier.gain]),
                          controller.joint_bounds.acceleration_limit, controller.dt)
    forward = -rows[0, 0]  # the point's approach per unit of the base's forward speed
    return min(float(model.velocityLimit[0]), -float(braked[0]) / forward)


def forward_push(robot, q: np.ndarray, speed: float) -> np.ndarray:
    """Both EE twists (LOCAL) moving the tools forward (world x) at ``speed``."""
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    twists = []
    for name in robot.ee_frames:
        rotation = data.oMf[model.getFrameId(name)].rotation
        twists.append(np.concatenate([rotation.T @ np.array([speed, 0.0, 0.0]), np.zeros(3)]))
    return np.concatenate(twists)


@pytest.mark.slow
@settings(max_examples=14, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(spec=st.sampled_from(SPECS), gap=st.floats(0.0, 0.3), fraction=st.floats(0.5, 1.0),
       push=st.floats(0.2, 2.0))
def test_a_base_at_its_top_speed_never_crosses_the_wall(mobile, spec, gap, fraction, push):
    """The base driving forward at ``fraction`` of the top speed the damper allows at
    ``gap``, both tools pulled forward at ``push`` m/s, on the ideal integrator (the brute
    force: 0.8 s at 500 Hz): the base's front never passes the wall (by more than 0.1 um,
    the first-order rows' error as the base turns a little under the push)."""
    model = mobile.model
    q = mobile.q_home.copy()
    barrier = front_barrier(mobile, q, gap)
    controller = make_controller(spec, mobile, [barrier], dt=DT, time_budget=None,
                                 acceleration_limit=ROBOT)
    controller.command_box.previous_command[0] = fraction * top_speed(controller, barrier, q)
    twist = forward_push(mobile, q, push)
    data = model.createData()
    base = model.getFrameId("mobile_base")
    for _ in range(400):
        qd = controller.solve(q, twist)
        assert np.all(np.isfinite(qd)), controller.info.message
        q = pin.integrate(model, q, qd * DT)
        pin.framesForwardKinematics(model, data, q)
        penetration = barrier.penetration(data.oMf[base])
        assert penetration <= 1e-7, (spec, penetration, controller.info.message)
