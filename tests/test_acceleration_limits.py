"""Acceleration limits in every controller (docs/design.md section 8.4).

* The braking-aware position bound against a brute-force simulation of braking, and its
  invariance (from a speed it allows, the next period's bound still allows braking).
* Every controller over sequences of steps on the ideal integrator, from rest, with random
  targets: no command leaves a joint's acceleration, velocity or position limit, and no
  step says ``ok`` while a hole's correction was cut.
* The CJM's scaled step against a null-space solution written here (a square system:
  the sda10f with one hole), and the two CJM backends equal with the limits on.
* The statuses, the controlled stop, the robots' limits, bad values and the loop's reset.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from constraints import Hole
from controllers import CJMController, QPController
from controllers.base import EQUALITY_TOLERANCE, StepStatus
from controllers.joint_acceleration import braking_speed
from controllers.joint_limits import JointBounds
from teleop import load_robot
from teleop.controller_specs import ROBOT, make_controller
from teleop.robots.chains import load_chain

SPECS = ("cjm", "cjm:python", "cjm:general", "qp:proxqp", "qp:daqp", "qp:osqp", "mink:daqp",
         "mink:proxqp")
ROBOTS = ("sda10f", "ur5_instrument", "sda10f_dual_mobile")
#: the controllers' box tolerance: 1e-9 of a joint's velocity limit (BoxTest)
SLACK = 1e-9


@pytest.fixture(scope="module")
def robots():
    return {name: load_robot(name) for name in ROBOTS}


def braked_to_a_stop(speed: float, distance: float, step: float, dt: float, gain: float) -> bool:
    """Brute force: command ``speed`` now, then slow by ``step`` a period to 0; every period
    covers at most ``gain`` of the distance left (the position bound's rule)."""
    left = distance
    while speed > 0.0:
        if speed * dt > gain * left * (1.0 + 1e-12):
            return False
        left -= speed * dt
        speed -= step
    return True


@settings(max_examples=200, deadline=None)
@given(distance=st.floats(0.0, 2.0), acceleration=st.floats(0.1, 100.0),
       dt=st.sampled_from([1e-3, 2e-3, 1e-2]), gain=st.floats(0.5, 1.0))
# a subnormal distance: the bound was 2.47e-321, above gain * distance / dt (0 in doubles)
@example(distance=5e-324, acceleration=1.0, dt=1e-3, gain=0.5)
@example(distance=2.2250738585072014e-308, acceleration=0.1, dt=1e-2, gain=1.0)  # the least normal
def test_braking_speed_is_the_largest_speed_that_can_still_stop(distance, acceleration, dt, gain):
    step = acceleration * dt
    bound = float(braking_speed(np.array([distance]), np.array([step]), dt, gain)[0])
    assert 0.0 <= bound <= gain * distance / dt * (1.0 + 1e-12)
    assert braked_to_a_stop(bound * (1.0 - 1e-9), distance, step, dt, gain)
    # the largest: 1e-6 relative faster (or, at distance 0, any speed) cannot stop in time
    faster = bound * (1.0 + 1e-6) + 1e-9 * step
    assert not braked_to_a_stop(faster, distance, step, dt, gain)


@settings(max_examples=200, deadline=None)
@given(distance=st.floats(1e-9, 2.0), fraction=st.floats(0.0, 1.0),
       acceleration=st.floats(0.1, 100.0), dt=st.sampled_from([1e-3, 1e-2]),
       gain=st.floats(0.5, 1.0))
# at the bound with gain 1, rounding made v dt exceed the distance (left -2.07e-25)
@example(distance=1.060395928589771e-09, fraction=1.0, acceleration=85.75468723109817,
         dt=1e-2, gain=1.0)
@example(distance=0.0003066433223308079, fraction=1.0, acceleration=69.65188909973531,
         dt=1e-2, gain=1.0)
def test_the_braking_bound_is_invariant(distance, fraction, acceleration, dt, gain):
    """From any speed it allows, one period on the bound's next value still admits the
    speed one acceleration step lower (the box never empties on the ideal integrator)."""
    step = acceleration * dt
    speed = fraction * float(braking_speed(np.array([distance]), np.array([step]), dt, gain)[0])
    left = distance - speed * dt
    assert left >= 0.0
    after = float(braking_speed(np.array([left]), np.array([step]), dt, gain)[0])
    assert speed - step <= after * (1.0 + 1e-9) + 1e-12


def test_a_joint_driven_at_its_bound_brakes_before_its_limit():
    """The sda10f's joints pushed at the top of their box each period, from rest, 0.3 rad
    from the upper limit: the command ramps, brakes, never leaves the acceleration box,
    never empties the box and never passes the limit."""
    robot = load_robot("sda10f")
    model = robot.model
    bounds = JointBounds(model, 1e-3, acceleration_limit=robot.acceleration_limit)
    q = model.upperPositionLimit - 0.3
    previous = np.zeros(model.nv)
    step = bounds.acceleration_step
    slack = SLACK * model.velocityLimit  # the controllers' box tolerance (rounding: 1e-13)
    for _ in range(3000):
        lower, upper = bounds.box(q, previous)
        assert np.all(upper >= previous - step - slack)  # the acceleration box is reached
        qd = upper
        assert np.all(np.abs(qd - previous) <= step + slack)
        q = q + qd * 1e-3
        assert np.all(q <= model.upperPositionLimit)
        previous = qd
    np.testing.assert_allclose(previous, 0.0, atol=1e-12)  # at rest at the limit
    assert np.all(model.upperPositionLimit - q < 1e-3)


def integrate(model: pin.Model, q: np.ndarray, qd: np.ndarray, dt: float) -> np.ndarray:
    return pin.integrate(model, q, qd * dt)


def check_step(controller, model, q, qd, previous, q_next):
    """The command within the acceleration, velocity and position limits."""
    step = controller.joint_bounds.acceleration_step
    velocity = controller.joint_bounds.velocity_limit
    slack = SLACK * np.where(np.isfinite(velocity), velocity, 1.0)
    assert np.all(np.isfinite(qd))
    assert np.all(np.abs(qd - previous) <= step + slack), np.abs(qd - previous) - step
    assert np.all(np.abs(qd) <= velocity + slack)
    bounds = controller.joint_bounds
    moved = q_next[bounds.limited_q]
    assert np.all(moved >= bounds.q_limits[0] - 1e-12) and np.all(moved <= bounds.q_limits[1] + 1e-12)


def hole_is_held(controller, q, qd) -> bool:
    """``A qd = b`` for every equality, the rows computed here at ``q``."""
    model = controller.model
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    for constraint in controller.constraints:
        if constraint.is_equality:
            A, b = constraint.rows(model, data, model.getFrameId(constraint.link))
            if float(np.max(np.abs(A @ qd - b))) > 1e3 * EQUALITY_TOLERANCE:
                return False
    return True


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(spec=st.sampled_from(SPECS), name=st.sampled_from(ROBOTS), seed=st.integers(0, 2**31),
       with_hole=st.booleans(), speed=st.floats(0.01, 2.0))
def test_no_command_leaves_an_acceleration_velocity_or_position_limit(
        robots, spec, name, seed, with_hole, speed):
    robot = robots[name]
    model = robot.model
    rng = np.random.default_rng(seed)
    q = robot.random_configuration(rng, margin=0.02)
    constraints = [Hole.on_link(robot, q, distance=0.05, link=link)
                   for link in robot.constrained_links] if with_hole else []
    controller = make_controller(spec, robot, constraints, time_budget=None,
                                 acceleration_limit=ROBOT)
    assert controller.joint_bounds.acceleration_limit is not None
    for k in range(40):
        if k % 10 == 0:  # a new random target direction every 10 ms
            twist = speed * rng.uniform(-1.0, 1.0, controller.task_size)
        previous = controller.command_box.previous_command.copy()
        qd = controller.solve(q, twist)
        q_next = integrate(model, q, qd, controller.dt)
        check_step(controller, model, q, qd, previous, q_next)
        if controller.info.status is StepStatus.OK:
            assert hole_is_held(controller, q, qd), (spec, controller.info.message)
        q = q_next


def square_scaled_step(A, b, J, twist, lower, upper):
    """The only commands holding the hole and moving the EE along ``twist`` on the sda10f
    (8 joints = 2 rows + 6) are ``base + s direction``; the largest ``s`` in [0, 1] whose
    command is inside the box."""
    M = np.vstack([A, J])
    base = np.linalg.solve(M, np.concatenate([b, np.zeros(6)]))
    direction = np.linalg.solve(M, np.concatenate([np.zeros(2), twist]))
    s = 1.0
    for i in range(len(base)):
        if direction[i] > 0:
            s = min(s, (upper[i] - base[i]) / direction[i])
        elif direction[i] < 0:
            s = min(s, (lower[i] - base[i]) / direction[i])
    return base + s * direction, s


@pytest.mark.parametrize("backend", ["python", "compiled"])
def test_the_cjm_walks_past_the_scaled_null_space_solution_written_here(backend):
    """With acceleration limits the CJM walks from the previous command (docs/design.md
    section 12): it holds the hole exactly, stays in the box, and misses the twist by no
    more than the best direction-keeping command written here (SNS's answer), which its
    walk passes through before the first joint reaches its bound."""
    robot = load_robot("sda10f")
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.05)
    cjm = CJMController(robot, [hole], backend=backend, acceleration_limit=robot.acceleration_limit)
    twist = np.array([0.3, -0.2, 0.1, 0.5, 0.2, -0.4])
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    A, b = hole.rows(model, data, model.getFrameId(hole.link))
    J = pin.getFrameJacobian(model, data, robot.ee_frame_id, pin.LOCAL)
    direction = np.linalg.solve(np.vstack([A, J]), np.concatenate([np.zeros(2), twist]))
    step = cjm.joint_bounds.acceleration_step
    # already moving along the task, at half what one acceleration step allows
    cjm.step.previous[:] = 0.5 * np.min(step / np.abs(direction)) * direction
    lower, upper = cjm.bounds(q)
    qd = cjm.solve(q, twist)
    scaled, s = square_scaled_step(A, b, J, twist, lower, upper)
    assert 0.0 < s < 1.0
    assert np.abs(A @ qd - b).max() <= 1e-12
    assert np.all(qd >= lower - 1e-12) and np.all(qd <= upper + 1e-12)
    assert np.linalg.norm(J @ qd - twist) <= np.linalg.norm(J @ scaled - twist)
    # the twist is not met along its direction: the status says least squares, and the
    # scale is the share of the twist J qd carries along it
    assert cjm.info.status is StepStatus.LEAST_SQUARES
    assert cjm.info.scale == pytest.approx(float(J @ qd @ twist) / float(twist @ twist), rel=1e-9)
    assert cjm.info.scale > s
    np.testing.assert_allclose(cjm.step.previous, qd)


@settings(max_examples=25, deadline=None)
@given(name=st.sampled_from(["sda10f", "sda10f_dual"]), seed=st.integers(0, 2**31),
       speed=st.floats(0.05, 3.0))
def test_python_and_compiled_steps_agree_with_acceleration_limits(name, seed, speed):
    robot = load_robot(name)
    rng = np.random.default_rng(seed)
    q = robot.random_configuration(rng, margin=0.05)
    holes = [Hole.on_link(robot, q, distance=0.05, link=link) for link in robot.constrained_links]
    steps = [CJMController(robot, holes, backend=backend, acceleration_limit=robot.acceleration_limit)
             for backend in ("python", "compiled")]
    for k in range(30):
        if k % 10 == 0:
            twist = speed * rng.uniform(-1.0, 1.0, steps[0].task_size)
            previous = rng.uniform(-1.0, 1.0, robot.nv) * robot.model.velocityLimit * 0.5
            for controller in steps:  # the same reference in both
                controller.step.previous[:] = previous
        python, compiled = (controller.solve(q, twist) for controller in steps)
        assert steps[0].info.status == steps[1].info.status
        np.testing.assert_allclose(compiled, python, rtol=0,
                                   atol=1e-9 * (1 + np.abs(python).max()))
        steps[1].step.previous[:] = python
        q = q + python * 1e-3


@pytest.mark.parametrize("spec", SPECS)
def test_a_binding_acceleration_limit_is_never_ok(spec):
    robot = load_robot("sda10f")
    q = robot.q_home.copy()
    controller = make_controller(spec, robot, [Hole.on_link(robot, q, distance=0.05)],
                                 time_budget=None, acceleration_limit=ROBOT)
    controller.solve(q, np.array([0.2, 0.0, 0.1, 0.0, 0.3, 0.0]))  # from rest
    assert controller.info.status in (StepStatus.SCALED, StepStatus.LEAST_SQUARES), spec
    assert hole_is_held(controller, q, controller.command_box.previous_command)


@pytest.mark.parametrize("spec", SPECS)
def test_a_hole_correction_that_cannot_fit_is_constraint_degraded(spec):
    """The hole 2 cm off the shaft asks 100/s x 2 cm = 2 m/s of correction; at 1e-3 rad/s^2
    the box from rest is 1e-6 rad/s wide: the correction is cut."""
    robot = load_robot("sda10f")
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.05)
    hole.center = hole.center + np.array([0.0, 0.02, 0.0])
    controller = make_controller(spec, robot, [hole], time_budget=None,
                                 acceleration_limit=np.full(robot.nv, 1e-3))
    qd = controller.solve(q, np.zeros(6))
    # the controllers' box tolerance, 1e-9 of the velocity limit (the QP's own is looser)
    assert np.all(np.abs(qd) <= 1e-6 + SLACK * robot.model.velocityLimit)
    assert not hole_is_held(controller, q, qd)
    assert controller.info.status in (StepStatus.CONSTRAINT_DEGRADED, StepStatus.FAILED), spec


@pytest.mark.parametrize("spec", ["cjm", "cjm:python", "qp:daqp", "mink:daqp"])
def test_the_stop_command_is_the_command_nearest_zero_in_the_box(spec):
    robot = load_robot("sda10f")
    q = robot.q_home.copy()
    controller = make_controller(spec, robot, [], time_budget=None, acceleration_limit=ROBOT)
    moving = np.linspace(-1.0, 1.0, robot.nv)
    controller.command_box.previous_command[:] = moving
    stop = controller.command_box.stop_command(q)
    step = controller.joint_bounds.acceleration_step
    np.testing.assert_allclose(stop, moving - np.sign(moving) * np.minimum(step, np.abs(moving)))
    lower, upper = controller.bounds(q)
    assert np.all(stop >= lower) and np.all(stop <= upper)


def test_the_loop_reset_resets_the_controller():
    from teleop.loop.closed_loop import TeleopLoop

    robot = load_robot("sda10f")
    controller = make_controller("cjm", robot, [], acceleration_limit=ROBOT)
    loop = TeleopLoop(robot, controller)
    controller.solve(robot.q_home, np.array([0.1, 0, 0, 0, 0, 0]))
    assert np.abs(controller.step.previous).max() > 0.0  # what the CJM's step counts from
    loop.reset()
    np.testing.assert_array_equal(controller.step.previous, 0.0)


def test_the_robots_have_acceleration_limits():
    sda10f = load_robot("sda10f")
    np.testing.assert_allclose(sda10f.acceleration_limit, sda10f.model.velocityLimit / 0.2)
    mobile = load_robot("sda10f_dual_mobile")
    assert mobile.acceleration_limit.shape == (mobile.nv,)
    np.testing.assert_allclose(mobile.acceleration_limit[:3], [1.0, 1.0, 2.0])
    chain = load_chain(64)  # from its URDF's <limit acceleration="15.0">
    np.testing.assert_array_equal(chain.acceleration_limit, np.full(64, 15.0))
    for name in ("ur5_instrument", "sda10f_dual"):
        robot = load_robot(name)
        assert robot.acceleration_limit.shape == (robot.nv,)
        assert np.all(np.isfinite(robot.acceleration_limit) & (robot.acceleration_limit > 0))


def test_an_acceleration_limit_from_the_urdf(tmp_path):
    text = load_robot("sda10f").urdf_path.read_text()
    first = text.index('velocity="', text.index("<limit"))
    path = tmp_path / "arm.urdf"
    path.write_text(text[:first] + 'acceleration="7.5" ' + text[first:])
    robot = load_robot(path, ee_frame="tool0")
    assert robot.acceleration_limit[0] == 7.5
    assert np.all(np.isinf(robot.acceleration_limit[1:]))
    path.write_text(text[:first] + 'acceleration="-1" ' + text[first:])
    with pytest.raises(ValueError, match="acceleration"):
        load_robot(path, ee_frame="tool0")


@pytest.mark.parametrize("value", [np.full(8, -1.0), np.full(8, np.nan), np.zeros(8),
                                   np.ones(3), "fast"])
def test_bad_acceleration_limits_are_refused(value):
    robot = load_robot("sda10f")
    with pytest.raises(ValueError, match="acceleration_limit"):
        QPController(robot, [], acceleration_limit=value)
    with pytest.raises(ValueError, match="acceleration_limit"):
        CJMController(robot, [], acceleration_limit=value)
    with pytest.raises(ValueError, match="acceleration_limit"):
        load_robot("sda10f", acceleration_limit=value)


def test_without_acceleration_limits_nothing_changes():
    """A direct construction (acceleration_limit None) gives today's box and command."""
    robot = load_robot("sda10f")
    q = robot.q_home.copy()
    plain = CJMController(robot, [Hole.on_link(robot, q, distance=0.05)])
    assert plain.joint_bounds.acceleration_limit is None
    twist = np.array([0.3, 0, 0, 0, 0, 0])
    first = plain.solve(q, twist)
    np.testing.assert_array_equal(plain.solve(q, twist), first)
    np.testing.assert_array_equal(plain.bounds(q)[0], plain.joint_bounds.box(q)[0])


@pytest.mark.parametrize("spec", ["cjm", "cjm:python", "qp:daqp", "mink:daqp"])
def test_without_acceleration_limits_the_stop_brings_a_joint_past_its_limit_back(spec):
    """Zero is outside the box of a joint past its position limit (the box asks it back):
    the stop is the command nearest zero inside it, not zero."""
    robot = load_robot("sda10f")
    q = robot.q_home.copy()
    q[2] = robot.model.lowerPositionLimit[2] - 0.03  # joint 2 below its lower limit
    controller = make_controller(spec, robot, [], time_budget=None)
    lower, upper = controller.joint_bounds.box(q)
    stop = controller.command_box.stop_command(q)
    np.testing.assert_array_equal(stop, np.clip(0.0, lower, upper))
    assert lower[2] > 0 and stop[2] == lower[2]  # back towards the limit
    assert np.count_nonzero(stop) == 1
