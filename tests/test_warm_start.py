"""The warm start of the saturation around the previous command (docs/design.md 9.1):
the last period's held joints tried first, accepted only at the walk's optimum. Checked
against the walk itself (a controller without the last period's held joints), the other
backend, and the optimum's conditions."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

import controllers.cjm.python_step as python_step
from constraints import Hole, Plane
from controllers import CJMController
from controllers.cjm.saturation_walk import held_sides, saturate_around_previous, saturate_from_held
from controllers.linalg import DampingPolicy
from teleop import load_robot
from teleop.experiments.bench_loop import ACCELERATION_SCENARIO, scenario_periods
from teleop.experiments.scenarios import load_scenario
from test_saturation_walk import hole_rows

ROBOTS = {name: load_robot(name) for name in ("sda10f", "sda10f_dual")}


def tolerance(qd: np.ndarray) -> float:
    """The backends' agreement (docs/design.md 16): 1e-8 (1 + |qd|)."""
    return 1e-8 * (1.0 + float(np.abs(qd).max()))


def draw_period(robot, rng: np.random.Generator, moving: float, speed_exponent: float,
                holdable: bool) -> tuple[np.ndarray, list[Hole], np.ndarray, np.ndarray]:
    """A configuration, a hole on each constrained link there, a twist of about
    ``10^speed_exponent`` and a previous command of up to ``moving`` times the velocity
    limits, moved to hold the holes' rows when ``holdable`` (a warm start follows a
    saturation only where they held)."""
    q = robot.random_configuration(rng, margin=0.05)
    holes = [Hole.on_link(robot, q, distance=0.05, link=link) for link in robot.constrained_links]
    twist = 10.0 ** speed_exponent * rng.uniform(-1.0, 1.0, 6 * len(robot.ee_frames))
    previous = moving * robot.model.velocityLimit * rng.uniform(-1.0, 1.0, robot.model.nv)
    if holdable:
        rows, rhs = hole_rows(robot, holes, q)
        previous -= np.linalg.pinv(rows) @ (rows @ previous - rhs)
    return q, holes, twist, previous


@settings(max_examples=80, deadline=None)
@given(name=st.sampled_from(sorted(ROBOTS)), seed=st.integers(0, 2**31),
       moving=st.floats(0.0, 1.0), speed_exponent=st.floats(-2.0, 3.0),
       change=st.floats(0.0, 0.3), holdable=st.booleans(), damping=st.sampled_from([0.0, 0.01]))
def test_the_warm_start_gives_the_walks_command(name, seed, moving, speed_exponent, change,
                                                holdable, damping):
    """Two periods in a row with the robot's acceleration limits: the second command (the
    warm start's wherever the first period saturated) equals the one of a controller
    that has not seen the first period, from the same previous command (the unsaturated
    form, then the walk), with its status and method, in both backends; and the backends
    agree. A constant damping (0.01) leaves the compiled step's warm start to the
    reference's solve (the SVD decides the DLS)."""
    robot = ROBOTS[name]
    rng = np.random.default_rng(seed)
    q, holes, twist, previous = draw_period(robot, rng, moving, speed_exponent, holdable)
    next_twist = twist * (1.0 + change * rng.uniform(-1.0, 1.0, twist.size))
    seconds = {}
    for backend in ("python", "compiled"):
        warm = CJMController(robot, holes, backend=backend, damping=damping,
                             acceleration_limit=robot.acceleration_limit)
        warm.step.previous[:] = previous
        first = warm.solve(q, twist)
        first_method = warm.info.method
        next_q = pin.integrate(robot.model, q, first * 1e-3)
        second = warm.solve(next_q, next_twist)
        cold = CJMController(robot, holes, backend=backend, damping=damping,
                             acceleration_limit=robot.acceleration_limit)
        cold.step.previous[:] = first
        walked = cold.solve(next_q, next_twist)
        np.testing.assert_allclose(second, walked, rtol=0, atol=tolerance(walked))
        assert warm.info.status is cold.info.status, (backend, warm.info.message, cold.info.message)
        assert warm.info.method == cold.info.method, backend
        seconds[backend] = second, warm.info.status
        event(f"first period {first_method}, second {warm.info.method}")
    np.testing.assert_allclose(seconds["compiled"][0], seconds["python"][0], rtol=0,
                               atol=tolerance(seconds["python"][0]))
    assert seconds["compiled"][1] is seconds["python"][1]


@pytest.fixture
def accepted(monkeypatch: pytest.MonkeyPatch) -> list[bool]:
    """Whether each warm start the Python step decided on was accepted, in order."""
    decisions: list[bool] = []

    def counted(*args):
        result = saturate_from_held(*args)
        decisions.append(result[0] is not None)
        return result

    monkeypatch.setattr(python_step, "saturate_from_held", counted)
    return decisions


def test_the_warm_start_is_taken_in_most_second_periods(accepted):
    """The property above's draws (rows held by the previous command, 40 seeds): the
    Python step accepts the warm start in most second periods, so that property compares
    it, not only the walk, with the walk."""
    for seed in range(40):
        robot = ROBOTS[sorted(ROBOTS)[seed % 2]]
        rng = np.random.default_rng(seed)
        q, holes, twist, previous = draw_period(robot, rng, rng.uniform(), rng.uniform(-2.0, 3.0),
                                                holdable=True)
        warm = CJMController(robot, holes, backend="python", acceleration_limit=robot.acceleration_limit)
        warm.step.previous[:] = previous
        first = warm.solve(q, twist)
        warm.solve(pin.integrate(robot.model, q, first * 1e-3), twist)
    assert sum(accepted) >= 20


def test_a_previous_command_written_ends_the_warm_start(monkeypatch):
    """After a saturated period, a previous command written from outside (a stop, a
    reset) is not the one the held joints came from: no warm start is tried."""
    calls = []
    monkeypatch.setattr(python_step, "saturate_from_held",
                        lambda *args: calls.append(1) or saturate_from_held(*args))
    robot = ROBOTS["sda10f"]
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.05)
    twist = np.array([0.3, -0.2, 0.1, 0.0, 0.0, 0.0])
    for written in (False, True):
        calls.clear()
        cjm = CJMController(robot, [hole], backend="python",
                            acceleration_limit=robot.acceleration_limit)
        cjm.solve(q, twist)
        assert cjm.info.method == "saturated" and cjm.info.saturated_joints
        if written:
            cjm.step.previous[:] = 0.0
        cjm.solve(q, twist)
        assert bool(calls) is not written


def test_fast_lateral_takes_the_warm_start_and_the_backends_agree(accepted):
    """fast-lateral's first 0.6 s with the acceleration limits: the Python step accepts the
    warm start in most of the periods it saturates, and the compiled step's commands and
    statuses are the Python step's, period by period."""
    plan = load_scenario(ACCELERATION_SCENARIO)
    configurations, twists = scenario_periods(ACCELERATION_SCENARIO, 0.6, acceleration_limits=True)
    steps = {backend: CJMController(plan.robot, plan.make_constraints(), backend=backend,
                                    acceleration_limit=plan.robot.acceleration_limit)
             for backend in ("python", "compiled")}
    saturated = 0
    for q, twist in zip(configurations, twists):
        python = steps["python"].solve(q, twist)
        compiled = steps["compiled"].solve(q, twist)
        np.testing.assert_allclose(compiled, python, rtol=0, atol=tolerance(python))
        assert steps["compiled"].info.message == steps["python"].info.message
        saturated += steps["python"].info.method == "saturated"
    assert saturated > 300
    assert sum(accepted) > 0.9 * saturated


def walk_problem(robot, constraint, seed: int):
    """A saturated walk on ``robot`` under ``constraint``'s rows at a random configuration
    and a fast twist: the rows, their right-hand side, the EE Jacobian, the twist, the box
    and the previous command, which holds the rows (Pinocchio; the box 0.05 rad/s wide
    around it)."""
    rng = np.random.default_rng(seed)
    model, data = robot.model, robot.model.createData()
    q = robot.random_configuration(rng, margin=0.2)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    rows, rhs = constraint(robot, q).rows(model, data, model.getFrameId(robot.constrained_link))
    jacobian = pin.getFrameJacobian(model, data, model.getFrameId(robot.ee_frame),
                                    pin.LOCAL_WORLD_ALIGNED)
    twist = rng.uniform(-0.5, 0.5, 6)
    previous = 0.2 * rng.uniform(-1.0, 1.0, model.nv)  # moved to hold the rows:
    previous -= np.linalg.pinv(rows) @ (rows @ previous - rhs)  # a feasible box
    return rows, rhs, jacobian, twist, previous - 0.025, previous + 0.025, previous


def test_saturate_from_held_accepts_the_optimum_and_nothing_else():
    """With the walk's own held joints the warm start returns the walk's command; holding
    one more joint (free and inside its box at the optimum) is refused; a plane's single
    row leaves ``J N`` wide (7 joints, 6 task rows), the optimum not unique: refused."""
    robot = ROBOTS["sda10f"]
    policy = DampingPolicy()
    checked = 0
    for seed in range(20):
        problem = walk_problem(robot, lambda robot, q: Hole.on_link(robot, q, distance=0.05), seed)
        walked = saturate_around_previous(*problem[:6], policy, problem[6])
        sides = held_sides(walked, problem[4], problem[5])
        if sides is None or not sides.any():
            continue
        warm, decided = saturate_from_held(*problem[:6], policy, sides, walked.limiting_joint)
        assert warm is not None and decided
        np.testing.assert_allclose(warm.qd, walked.qd, rtol=0, atol=tolerance(walked.qd))
        assert warm.saturated == walked.saturated
        lower, upper = problem[4], problem[5]
        inside = np.flatnonzero((sides == 0) & (walked.qd > lower + 1e-6) & (walked.qd < upper - 1e-6))
        if inside.size:
            more = sides.copy()
            more[inside[0]] = 1
            assert saturate_from_held(*problem[:6], policy, more, -1) == (None, True)
        checked += 1
    assert checked >= 5
    plane = walk_problem(robot, lambda robot, q: Plane.through_link_point(
        robot, q, normal=[0.0, 0.0, 1.0], distance=0.05), 0)
    assert saturate_from_held(*plane[:6], policy, np.zeros(robot.model.nv, dtype=int), -1) == (
        None, False)
