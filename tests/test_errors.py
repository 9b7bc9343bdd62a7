"""Bad input gets a clear error; numerical failure gets a flagged zero command, never NaN."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import kinematics

from constraints import Barrier, Hole, Plane, PointLock
from controllers import CJMController, QPController, SolverError, StepStatus


@pytest.fixture()
def setup(sda10f):
    q = sda10f.q_home.copy()
    return sda10f, q, Hole.on_link(sda10f, q, distance=0.08)


def test_unknown_link_is_named(setup):
    robot, q, _ = setup
    with pytest.raises(ValueError, match="unknown link 'forearm'"):
        Hole.on_link(robot, q, distance=0.1, link="forearm")
    with pytest.raises(ValueError, match="unknown link 'nowhere'"):
        CJMController(robot, [Hole("nowhere", [0, 0, 0])])
    with pytest.raises(ValueError, match="unknown link 'nowhere'"):
        QPController(robot, [Plane("nowhere", [0, 0, 0], [0, 0, 0], [0, 0, 1])])


def test_hole_off_the_link_axis_says_by_how_much(setup):
    robot, q, hole = setup
    data = kinematics(robot, q)
    rotation = data.oMf[robot.model.getFrameId(robot.constrained_link)].rotation
    sideways = rotation @ np.array([1.0, 0.0, 0.0])  # across the link axis (-z of the link)
    with pytest.raises(ValueError, match=r"off the axis of link 'arm_link_5_r' by 0\.012 m"):
        Hole.at(robot, q, hole.center + 0.012 * sideways)
    assert Hole.at(robot, q, hole.center + 1e-5 * sideways).center is not None  # within tolerance


def test_plane_the_point_is_not_on_is_refused(setup):
    robot, q, hole = setup
    with pytest.raises(ValueError, match=r"0\.05 m from the plane"):
        Plane.through_link_point(robot, q, normal=[0, 0, 1], distance=0.08,
                                 plane_point=hole.center + [0, 0, 0.05])
    with pytest.raises(ValueError, match="wrong side of the barrier"):
        Barrier.through_link_point(robot, q, normal=[0, 0, 1], distance=0.08,
                                   plane_point=hole.center + [0, 0, 0.05])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_twist_is_refused(setup, bad):
    robot, q, hole = setup
    twist = np.zeros(6)
    twist[3] = bad
    for controller in (CJMController(robot, [hole]), QPController(robot, [hole])):
        with pytest.raises(ValueError, match="twist must be finite"):
            controller.solve(q, twist)
    q_bad = q.copy()
    q_bad[0] = np.nan
    with pytest.raises(ValueError, match="q must be finite"):
        CJMController(robot, [hole]).solve(q_bad, np.zeros(6))


def test_wrong_sizes_are_refused(setup):
    robot, q, hole = setup
    controller = CJMController(robot, [hole])
    with pytest.raises(ValueError, match=r"twist must have shape \(6,\), got \(5,\)"):
        controller.solve(q, np.zeros(5))
    with pytest.raises(ValueError, match=r"q must have shape \(8,\), got \(7,\)"):
        controller.solve(q[:7], np.zeros(6))
    with pytest.raises(ValueError, match=r"hole center must have shape \(3,\)"):
        Hole("arm_link_5_r", [0.0, 0.0])
    with pytest.raises(ValueError, match=r"link_point must have shape \(3,\)"):
        PointLock("arm_link_5_r", [0.0, 0.0, 0.0, 1.0], [0, 0, 0])


@pytest.mark.parametrize("normal, message", [
    ([0.0, 0.0, 0.0], "zero vector"),
    ([0.0, 0.0, 2.0], "norm 2"),
    ([0.0, np.nan, 1.0], "must be finite"),
])
def test_bad_normals_are_refused(normal, message):
    with pytest.raises(ValueError, match=message):
        Plane("arm_link_5_r", [0, 0, 0], [0, 0, 0], normal)
    with pytest.raises(ValueError, match=message):
        Barrier("arm_link_5_r", [0, 0, 0], [0, 0, 0], normal)
    with pytest.raises(ValueError, match=message):
        Hole("arm_link_5_r", [0, 0, 0], link_axis=normal)


def test_bad_settings_are_refused(setup):
    robot, _, hole = setup
    with pytest.raises(ValueError, match="not available"):
        QPController(robot, [hole], solver="cplex-9000")
    with pytest.raises(ValueError, match="gain must be"):
        Hole("arm_link_5_r", [0, 0, 0], gain=-1.0)
    with pytest.raises(ValueError, match="damping must be"):
        CJMController(robot, [hole], damping=np.nan)
    with pytest.raises(ValueError, match="parametrisation"):
        CJMController(robot, [hole], parametrisation="euler")
    with pytest.raises(ValueError, match="must hold Constraint objects"):
        CJMController(robot, ["hole"])


def conflicting_locks(robot, q):
    """The same link point locked at two places 1 cm apart: no qd satisfies both."""
    lock = PointLock.on_link(robot, q, distance=0.05)
    other = PointLock(lock.link, lock.link_point, lock.target + [0.01, 0.0, 0.0])
    return [lock, other]


#: Iteration caps of one: no backend finishes a point lock's step in them.
ONE_ITERATION = {"daqp": {"iter_limit": 1}, "proxqp": {"max_iter": 1}, "osqp": {"max_iter": 1}}


@pytest.mark.parametrize("solver", ["proxqp", "daqp", "osqp"])
def test_conflicting_locks_in_the_qp_are_held_at_their_least_residual(setup, solver):
    """No qd holds both locks: the least residual (docs/design.md 10.7) splits the 1 m/s
    conflict (1 cm, K = 100 1/s), 0.5 m/s each, and says so."""
    robot, q, _ = setup
    controller = QPController(robot, conflicting_locks(robot, q), solver=solver,
                              time_budget=None)
    qd = controller.solve(q, np.full(6, 0.01))
    assert controller.info.status is StepStatus.CONSTRAINT_DEGRADED
    assert "least residual, 5.00e-01 m/s" in controller.info.message
    A, b = controller.constraint_rows([0, 1])
    assert np.max(np.abs(A @ qd - b)) == pytest.approx(0.5, abs=1e-6)


@pytest.mark.parametrize("solver", ["proxqp", "daqp", "osqp"])
def test_a_qp_that_cannot_finish_returns_a_flagged_zero_command(setup, solver):
    """The same locks with every solve capped at one iteration: nothing is found."""
    robot, q, _ = setup
    controller = QPController(robot, conflicting_locks(robot, q), solver=solver,
                              solver_settings=ONE_ITERATION[solver])
    qd = controller.solve(q, np.full(6, 0.01))
    assert not controller.info.success
    assert solver in controller.info.message
    np.testing.assert_array_equal(qd, np.zeros(robot.model.nv))
    strict = QPController(robot, conflicting_locks(robot, q), solver=solver, strict=True,
                          solver_settings=ONE_ITERATION[solver])
    with pytest.raises(SolverError, match=solver):
        strict.solve(q, np.full(6, 0.01))


def test_conflicting_constraints_in_the_cjm_give_a_finite_least_squares_command(setup):
    robot, q, _ = setup
    controller = CJMController(robot, conflicting_locks(robot, q))
    qd = controller.solve(q, np.full(6, 0.01))
    assert np.all(np.isfinite(qd))
    assert "conflict" in controller.info.message
