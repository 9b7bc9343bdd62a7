"""mink under the project's joint box (controllers/mink/joint_box.py, docs/design.md 10.7).

A joint 0.1 rad past a position limit: mink's stock ConfigurationLimit and VelocityLimit
have no common point there; the joint box pins that joint at its velocity limit back
towards the range. References: the model's velocity limits (read here), ``JointBounds.box``
and the QP controller (``qp:daqp``), which has always used the box.
"""

from __future__ import annotations

import math

import mink
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from constraints import Hole
from controllers import MinkController, QPController
from controllers.base import StepStatus
from teleop import load_robot

ROBOTS = ("sda10f", "ur5_instrument", "sda10f_dual_mobile")
PAST = 0.1  # rad beyond the bound
PROPERTY = settings(max_examples=30, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])

#: How far a command may sit from the box's bound (rad/s): the solvers' primal tolerances on
#: ``v`` (controllers.mink.settings.VELOCITY_TOLERANCES, at most 1e-10) with a margin; the
#: base class clips anything beyond rounding (and then degrades the step).
BOUND_TOLERANCE = 1e-8


@pytest.fixture(scope="module")
def robots():
    return {name: load_robot(name) for name in ROBOTS}


def limited_joints(model) -> list[tuple[int, int]]:
    """``(q index, v index)`` of the 1-dof joints with finite position limits."""
    return [(int(model.idx_qs[j]), int(model.idx_vs[j])) for j in range(1, model.njoints)
            if model.nqs[j] == 1 and model.nvs[j] == 1
            and np.isfinite(model.lowerPositionLimit[model.idx_qs[j]])
            and np.isfinite(model.upperPositionLimit[model.idx_qs[j]])]


def past_a_limit(robot, pick: int, side: int, heading: float) -> tuple[np.ndarray, int]:
    """``robot.q_home`` with one limited joint ``PAST`` rad beyond its bound on ``side``
    (+1 upper, -1 lower) and a planar base turned to ``heading``; the joint's v index."""
    model = robot.model
    q = robot.q_home.copy()
    joints = limited_joints(model)
    qi, vi = joints[pick % len(joints)]
    bound = model.upperPositionLimit[qi] if side > 0 else model.lowerPositionLimit[qi]
    q[qi] = bound + side * PAST
    if model.joints[1].shortname() == "JointModelPlanar":
        start = model.idx_qs[1]
        q[start + 2:start + 4] = math.cos(heading), math.sin(heading)
    return q, vi


@PROPERTY
@given(name=st.sampled_from(ROBOTS), pick=st.integers(0, 100), side=st.sampled_from([-1, 1]),
       heading=st.floats(-math.pi, math.pi), scale=st.floats(-3.0, 3.0),
       direction=st.lists(st.floats(-1.0, 1.0), min_size=12, max_size=12),
       with_hole=st.booleans(), solver=st.sampled_from(["daqp", "proxqp"]))
def test_past_a_limit_mink_brings_the_joint_back_like_the_qp(
        robots, name, pick, side, heading, scale, direction, with_hole, solver):
    robot = robots[name]
    q, joint = past_a_limit(robot, pick, side, heading)
    holes = [Hole.on_link(robot, robot.q_home, distance=0.08)] if with_hole else []
    qp = QPController(robot, holes, solver="daqp", time_budget=None)
    controller = MinkController(robot, holes, solver=solver, time_budget=None)
    twist = 10.0**scale * np.array(direction[:controller.task_size])
    qd = controller.solve(q, twist)
    reference = qp.solve(q, twist)
    assert controller.info.status is not StepStatus.FAILED, controller.info.message
    assert np.all(np.isfinite(qd))
    lower, upper = controller.bounds(q)
    assert np.all(qd >= lower - BOUND_TOLERANCE) and np.all(qd <= upper + BOUND_TOLERANCE)
    # the box pins the joint at its velocity limit, back towards its range, as the QP's
    back = -side * robot.model.velocityLimit[joint]
    assert qd[joint] == pytest.approx(back, abs=BOUND_TOLERANCE)
    assert qp.info.status is not StepStatus.FAILED
    assert reference[joint] == pytest.approx(back, abs=BOUND_TOLERANCE)


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("solver", ["daqp", "proxqp"])
def test_mink_stock_limits_have_no_common_point_past_a_limit(robots, solver):
    """Why the box: mink's own limits (limit gain 0.95) fail at the same configuration,
    with no constraint at all, where the default (the box) brings the joint back (and so
    cannot hold the EE still: least squares)."""
    robot = robots["sda10f"]
    q, joint = past_a_limit(robot, 3, 1, 0.0)
    velocity = robot.model.velocityLimit
    stock = MinkController(robot, solver=solver, time_budget=None, limits=[
        lambda model: mink.ConfigurationLimit(model, gain=0.95),
        lambda model: mink.VelocityLimit(model, {
            model.joint(i).name: velocity[i] for i in range(model.njnt)})])
    stock.solve(q, np.zeros(6))
    assert stock.info.status is StepStatus.FAILED
    boxed = MinkController(robot, solver=solver, time_budget=None)
    qd = boxed.solve(q, np.zeros(6))
    assert boxed.info.status is StepStatus.LEAST_SQUARES  # the pinned joint moves the EE
    assert qd[joint] == pytest.approx(-velocity[joint], abs=BOUND_TOLERANCE)
