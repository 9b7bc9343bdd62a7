"""Jacobians, constraint rows and errors against finite differences of Pinocchio FK."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import HOLE_DISTANCE, ee_jacobian, kinematics, near_home

from constraints import Barrier, Hole, Plane, PointLock
from controllers import CJMController

STEP = 1e-7


def placement_after(robot, q, qd, frame, h=STEP) -> pin.SE3:
    """World placement of ``frame`` after moving ``h`` along ``qd`` (forward kinematics only)."""
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.integrate(model, q, h * qd))
    return data.oMf[model.getFrameId(frame)].copy()


def make_constraints(robot, q, rng):
    link = robot.constrained_link
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    plane = Plane.through_link_point(robot, q, normal=normal, link_point=rng.normal(size=3) * 0.05)
    lock = PointLock.on_link(robot, q, distance=0.05)
    barrier = Barrier(link, [0.0, 0.0, 0.03], [0.0, 0.0, -1.0], normal)
    return [hole, plane, lock, barrier]


@pytest.mark.parametrize("seed", range(3))
def test_ee_jacobian_matches_finite_differences(robot, seed):
    rng = np.random.default_rng(seed)
    q = near_home(robot, rng)
    qd = rng.normal(size=robot.model.nv)
    before = kinematics(robot, q).oMf[robot.model.getFrameId(robot.ee_frame)]
    after = placement_after(robot, q, qd, robot.ee_frame)
    twist_fd = pin.log6(before.actInv(after)).vector / STEP  # body twist, LOCAL
    np.testing.assert_allclose(ee_jacobian(robot, q) @ qd, twist_fd, atol=1e-5)


@pytest.mark.parametrize("seed", range(3))
def test_constraint_rows_match_finite_differences_of_the_point(robot, seed):
    """``A qd`` is ``C`` times the finite-difference velocity of the material point."""
    rng = np.random.default_rng(10 + seed)
    q = near_home(robot, rng)
    qd = rng.normal(size=robot.model.nv)
    data = kinematics(robot, q)
    for constraint in make_constraints(robot, q, rng):
        frame = robot.model.getFrameId(constraint.link)
        placement = data.oMf[frame]
        state = constraint.evaluate(placement)
        point_world_before = placement.act(state.p)
        point_world_after = placement_after(robot, q, qd, constraint.link).act(state.p)
        velocity_local = placement.rotation.T @ (point_world_after - point_world_before) / STEP
        A, _ = constraint.rows(robot.model, data)
        np.testing.assert_allclose(A @ qd, state.C @ velocity_local, atol=2e-6,
                                   err_msg=type(constraint).__name__)


@pytest.mark.parametrize("seed", range(3))
def test_error_rate_matches_the_rows_at_zero_error(robot, seed):
    """Starting on the constraint, d/dt e(q(t)) = A qd: the drift term has the right sign."""
    rng = np.random.default_rng(20 + seed)
    q = near_home(robot, rng)
    qd = rng.normal(size=robot.model.nv)
    data = kinematics(robot, q)
    for constraint in make_constraints(robot, q, rng)[:3]:  # built with zero error
        frame = robot.model.getFrameId(constraint.link)
        assert np.allclose(constraint.error(data.oMf[frame]), 0.0, atol=1e-12)
        error_after = constraint.error(placement_after(robot, q, qd, constraint.link))
        A, _ = constraint.rows(robot.model, data)
        np.testing.assert_allclose(A @ qd, error_after / STEP, atol=2e-6,
                                   err_msg=type(constraint).__name__)


def test_cjm_matches_finite_differences_of_the_chain(robot):
    """``Jbar v_m`` equals the FD EE twist produced by the joint velocities it yields."""
    rng = np.random.default_rng(3)
    q = near_home(robot, rng)
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    controller = CJMController(robot, [hole], singular_threshold=0.0, velocity_limits=False,
                               position_limits=False)
    twist = rng.normal(size=6) * 0.05
    qd = controller.solve(q, twist)
    before = kinematics(robot, q).oMf[robot.model.getFrameId(robot.ee_frame)]
    after = placement_after(robot, q, qd, robot.ee_frame)
    np.testing.assert_allclose(pin.log6(before.actInv(after)).vector / STEP, twist, atol=1e-6)
    # and the hole point does not move sideways, to first order
    error_after = hole.error(placement_after(robot, q, qd, hole.link))
    assert np.max(np.abs(error_after)) / STEP < 1e-6


def test_sliding_contact_point_is_recomputed(ur5_instrument):
    """Moving the shaft along its axis moves the contact point, not the hole."""
    robot = ur5_instrument
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.2)
    frame = robot.model.getFrameId(hole.link)
    placement = kinematics(robot, q).oMf[frame]
    pushed = pin.SE3(placement.rotation, placement.translation + placement.rotation @ [0, 0, 0.03])
    np.testing.assert_allclose(hole.point(placement), [0, 0, 0.2], atol=1e-12)
    np.testing.assert_allclose(hole.point(pushed), [0, 0, 0.17], atol=1e-12)
    np.testing.assert_allclose(hole.error(pushed), 0.0, atol=1e-12)
