"""Chains the paper's 6-before/2-after case does not cover: fewer or more joints before
the constraint, redundancy, and URDFs from another package (example-robot-data)."""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest
from conftest import ee_jacobian, kinematics
from example_robots import EXAMPLE_ARMS, bounded_margins, singular_values

from constraints import Hole
from controllers import CJMController, QPController
from teleop import load_robot
from teleop.loop import LoopConfig, TeleopLoop, saturate_twist
from teleop.robots.catalog import example_robot_data_share

EXACT = dict(singular_threshold=0.0, velocity_limits=False, position_limits=False)
#: the QP carries the CJM's damping (docs/design.md 10.7): undamped where compared with EXACT
UNDAMPED = dict(singular_threshold=0.0)


@pytest.fixture(scope="module")
def ur5():
    share = example_robot_data_share()
    urdf = share / "example-robot-data/robots/ur_description/urdf/ur5_robot.urdf"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the meshes must be found through package_dirs
        robot = load_robot(urdf, ee_frame="tool0", constrained_link="forearm_link",
                           link_axis=(0, 0, 1), package_dirs=[str(share)],
                           q_home=[0.3, -1.2, 1.6, -1.8, -1.5, 0.4])
    assert len(robot.visual_model.geometryObjects) > 0
    return robot


@pytest.fixture(scope="module")
def panda():
    share = example_robot_data_share()
    urdf = share / "example-robot-data/robots/panda_description/urdf/panda.urdf"
    forearm = np.array([-0.0825, 0.384, 0.0])  # from joint 4 to joint 5, panda_link4 frame
    return load_robot(urdf, ee_frame="panda_hand", constrained_link="panda_link4",
                      link_axis=forearm / np.linalg.norm(forearm), package_dirs=[str(share)],
                      q_home=[0.2, -0.3, 0.1, -2.0, 0.2, 1.8, 0.7, 0.02, 0.02])


def constraint_residual(robot, q, constraint, qd):
    A, b = constraint.rows(robot.model, kinematics(robot, q))
    return float(np.max(np.abs(A @ qd - b)))


def test_ur5_forearm_hole_three_joints_before_least_squares_in_both(ur5):
    """3 joints before the hole: F_a cannot take any twist; 4 free DoF < 6 (least squares)."""
    q = ur5.q_home.copy()
    hole = Hole.on_link(ur5, q, distance=0.2)
    twist = np.array([0.02, -0.01, 0.01, 0.05, 0.02, -0.03])
    cjm = CJMController(ur5, [hole], **EXACT)
    qd = cjm.solve(q, twist)
    assert cjm.info.method == "general"
    assert constraint_residual(ur5, q, hole, qd) <= 1e-12
    J = ee_jacobian(ur5, q)
    assert np.linalg.norm(J @ qd - twist) > 1e-3  # not every twist is reachable...
    # ...and what is reached is the least-squares optimum: the residual is orthogonal to
    # every admissible direction J N.
    A, _ = hole.rows(ur5.model, kinematics(ur5, q))
    N = np.linalg.svd(A)[2][2:].T
    np.testing.assert_allclose((J @ N).T @ (J @ qd - twist), 0.0, atol=1e-12)
    for solver in ("proxqp", "daqp"):
        np.testing.assert_allclose(
            QPController(ur5, [hole], solver=solver, **UNDAMPED).solve(q, twist), qd, atol=1e-6)


def test_sda10f_hole_on_link_7_uses_the_pseudo_inverse_of_a_7_joint_pre_chain(sda10f):
    """Hole on the link joint B drives: 7 joints before, 1 after, Jbar 6 x 5."""
    q = sda10f.q_home.copy()
    hole = Hole.on_link(sda10f, q, distance=0.05, link="arm_link_6_b", link_axis=(0, 1, 0))
    twist = np.array([0.01, -0.01, 0.02, 0.03, 0.02, -0.01])
    cjm = CJMController(sda10f, [hole], **EXACT)
    qd = cjm.solve(q, twist)
    assert cjm.info.method == "analytical"
    assert cjm.constrained_jacobian(q).shape == (6, 5)
    assert constraint_residual(sda10f, q, hole, qd) <= 1e-12
    J = ee_jacobian(sda10f, q)
    # the achieved twist is unique (least squares), the joint motion is not: compare twists
    reached_general = J @ CJMController(sda10f, [hole], form="general", **EXACT).solve(q, twist)
    np.testing.assert_allclose(J @ qd, reached_general, atol=1e-9)
    for solver in ("proxqp", "daqp"):
        qp = QPController(sda10f, [hole], solver=solver, **UNDAMPED)
        np.testing.assert_allclose(J @ qp.solve(q, twist), J @ qd, atol=1e-6)
    # the posture task moves only the null space of J_a: same twist at F_a and EE
    no_posture = CJMController(sda10f, [hole], posture_gain=0.0, **EXACT).solve(q, twist)
    q_off = q.copy()
    q_off[:7] += 0.1
    assert np.linalg.norm(qd - no_posture) < 1e-12  # at home the posture task is idle
    moved = CJMController(sda10f, [hole], **EXACT).solve(q_off, twist)
    still = CJMController(sda10f, [hole], posture_gain=0.0, **EXACT).solve(q_off, twist)
    assert np.linalg.norm(moved - still) > 1e-3
    J_off = ee_jacobian(sda10f, q_off)
    np.testing.assert_allclose(J_off @ moved, J_off @ still, atol=1e-10)


def test_panda_forearm_hole_leaves_five_dof_and_both_controllers_reach_the_same_twist(panda):
    """4 joints before, 3 after, 2 fingers that move nothing: 7 - 2 = 5 DoF for the EE."""
    q = panda.q_home.copy()
    hole = Hole.on_link(panda, q, distance=0.2)
    twist = np.array([0.02, 0.01, -0.01, 0.05, -0.02, 0.03])
    cjm = CJMController(panda, [hole], **EXACT)
    qd = cjm.solve(q, twist)
    assert cjm.info.method == "general"
    assert constraint_residual(panda, q, hole, qd) <= 1e-12
    J = ee_jacobian(panda, q)
    A, _ = hole.rows(panda.model, kinematics(panda, q))
    N = np.linalg.svd(A)[2][2:].T
    assert np.linalg.matrix_rank(J @ N, tol=1e-9) == 5
    np.testing.assert_allclose((J @ N).T @ (J @ qd - twist), 0.0, atol=1e-12)  # least squares
    np.testing.assert_allclose(qd[7:], 0.0, atol=1e-12)  # fingers: posture at home, idle
    for solver in ("proxqp", "daqp"):
        qp = QPController(panda, [hole], solver=solver, **UNDAMPED)
        qd_qp = qp.solve(q, twist)
        assert qp.info.equality_residual <= 1e-9
        np.testing.assert_allclose(J @ qd_qp, J @ qd, atol=1e-6)


def test_plane_on_sda10f_leaves_seven_dof_and_the_wide_cjm_tracks_exactly(sda10f):
    """The paper's plane (1 equality) on link 6 of 8 joints: Jbar is 6 x 7."""
    from constraints import Plane

    q = sda10f.q_home.copy()
    plane = Plane.through_link_point(sda10f, q, normal=[0.0, 0.0, 1.0], distance=0.08)
    twist = np.array([0.02, 0.01, -0.01, 0.05, -0.02, 0.03])
    J = ee_jacobian(sda10f, q)
    for form in ("auto", "general"):
        cjm = CJMController(sda10f, [plane], form=form, **EXACT)
        qd = cjm.solve(q, twist)
        assert cjm.info.method == ("general" if form == "general" else "analytical")
        assert constraint_residual(sda10f, q, plane, qd) <= 1e-12
        np.testing.assert_allclose(J @ qd, twist, atol=1e-10)
    assert CJMController(sda10f, [plane]).constrained_jacobian(q).shape == (6, 7)
    qd_qp = QPController(sda10f, [plane], solver="proxqp").solve(q, twist)
    np.testing.assert_allclose(J @ qd_qp, twist, atol=1e-6)


def damped_least_squares(matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``matrix x`` for the CJM's default damping (paper eq 35: lambda rises to 0.05 as the
    smallest singular value falls below 0.01), written out with an SVD. Values at or below
    1e-10 relative (a structural zero: the Panda's fingers, off the hand's path) are
    dropped, and the smallest value kept decides the damping (docs/design.md section 4.2)."""
    u, s, vt = np.linalg.svd(matrix, full_matrices=False)
    kept = s > 1e-10 * max(1.0, s[0])
    lam2 = 0.05**2 * max(0.0, 1.0 - (s[kept][-1] / 0.01) ** 2)
    gains = np.where(kept, s / (s * s + lam2 + ~kept), 0.0)  # no 0/0 where dropped
    return matrix @ (vt.T @ (gains * (u.T @ rhs)))


@pytest.mark.parametrize("name", sorted(EXAMPLE_ARMS))
def test_a_40_mm_drag_from_the_default_home_moves_the_ee_and_no_joint_reaches_a_limit(name):
    """Found in review: from the neutral pose clipped to the limits the Panda's joint 4
    sat at its bound and a drag did not move the hand. From the default home (docs/design.md
    section 6.1), with a hole 8 cm along the link: a 40 mm target step along each world
    axis, followed for 1 s by the closed loop at 1 kHz with the default CJM, at 5 cm/s
    (under the Kinova's 0.63 rad/s joint speeds). The first step's EE twist (its speed
    capped) is the (damped) least-squares one over the joint velocities the hole admits,
    computed here with NumPy: no joint limit in it; on no step is a joint held at a limit;
    the joints stay 5 % of their range inside; the constrained Jacobian stays above 0.05
    (five times the CJM's damping threshold); the hole holds; the EE moves."""
    arm = EXAMPLE_ARMS[name]
    robot = arm.load()
    link = robot.model.getFrameId(robot.constrained_link)
    for direction in np.vstack([np.eye(3), -np.eye(3)]):
        hole = Hole.on_link(robot, robot.q_home, distance=0.08)
        cjm = CJMController(robot, [hole])
        loop = TeleopLoop(robot, cjm, config=LoopConfig(max_linear_speed=0.05,
                                                        max_angular_speed=0.3))
        start = loop.ee_placement()
        target = pin.SE3(start.rotation, start.translation + 0.04 * direction)
        twist = saturate_twist(loop.config.kp * pin.log6(start.actInv(target)).vector,
                               loop.config.max_linear_speed, loop.config.max_angular_speed)
        A, _ = hole.rows(robot.model, kinematics(robot, robot.q_home))
        admissible = ee_jacobian(robot, robot.q_home) @ np.linalg.svd(A)[2][2:].T
        expected = damped_least_squares(admissible, twist)
        for tick in range(1000):
            q = loop.q.copy()
            record = loop.tick(target)
            if tick == 0:
                np.testing.assert_allclose(ee_jacobian(robot, q) @ loop.last_qd, expected,
                                           atol=1e-9 * np.linalg.norm(twist))
            assert cjm.info.saturated_joints == (), (name, direction, tick, record.message)
            assert record.constraint_error < 1e-6
        assert min(bounded_margins(robot.model, loop.q).values()) > 0.05
        data = kinematics(robot, loop.q)
        contact = robot.link_axis @ data.oMf[link].actInv(hole.center)  # slid along the link
        constrained = singular_values(robot, loop.q, contact)[1]
        assert constrained[arm.free_dof - 1] > 0.05
        assert np.linalg.norm(loop.ee_placement().translation - start.translation) > 2e-3
