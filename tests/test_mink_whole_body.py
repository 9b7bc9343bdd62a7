"""MinkController on whole-body robots (docs/design.md section 11): two end effectors through
two trocars on one torso, and a planar mobile base.

References independent of mink: the CJM and the QP controller, Pinocchio's LOCAL frame
Jacobians, finite differences of MuJoCo's forward kinematics through ``pin.integrate`` (the
planar joint's configuration is not its velocity), and SciPy's null space of the hole rows.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from conftest import kinematics

from constraints import Hole
from controllers import CJMController, MinkController, QPController
from controllers.base import StepStatus
from controllers.mujoco_model import site_name
from teleop import load_robot

HOLE_DISTANCE = 0.08
SEEDS = st.integers(0, 2**32 - 1)
HEADINGS = st.floats(-math.pi, math.pi)
PROPERTY = settings(max_examples=25, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])

#: The exact stacked CJM: no damping near singularities (its 0.01 threshold would bend
#: the answer there, and this compares solvers, not regularisations).
EXACT_CJM = dict(singular_threshold=0.0)

#: mink against the CJM and the QP, two arms with a hole each (rad/s). 15 joints, 4 hole
#: rows, 12 task rows: a twist consistent with the holes has exactly one ``qd``, so the
#: posture plays no part and only mink's floor of the single-EE case remains (mink's SE(3)
#: ``jlog``, ~1e-9 m/s on ``J_e qd``, over the smallest singular value of ``J_e`` on the
#: holes' null space, >= 9e-3 here). Measured on 150 random configurations within 0.3 rad
#: of home and twists up to 0.3 rad/s per joint: 2.8e-7 (median 6e-8).
TWO_ARM_AGREEMENT = 1e-6

#: The same on the mobile base (rad/s): 18 joints leave 2 directions to the posture, which
#: mink weighs (cost ``c^2 = 1e-10 s``) where the CJM and the QP put it last
#: (docs/design.md section 10.5: 3e-6 on the 16-DoF chains). Measured on 150 random
#: configurations: 1.5e-6 (median 3e-7); the CJM and the QP agree to 2e-10.
MOBILE_AGREEMENT = 1e-5

#: mink's pure base motion against the commanded base velocity (m/s, rad/s). The base
#: link's Jacobian is an isometry on ``(v_x, v_y, w)``, so only mink's ``jlog`` floor
#: remains: ``Jlog`` wrong by ~1e-7 relative (tests/test_mink.py ``AGREEMENT``), times
#: ``|V| <= 1.1``. Measured up to 1e-9.
BASE_AGREEMENT = 1e-7


@pytest.fixture(scope="module")
def mobile_controller(mobile):
    """A mink controller of the mobile robot (its model and joint map), no constraint."""
    return MinkController(mobile)


@pytest.fixture(scope="module")
def mobile_left_arm():
    """The mobile robot with the left tool as the only end effector."""
    return load_robot("sda10f_dual_mobile", ee_frames=("arm_left_link_tool0",))


@pytest.fixture(scope="module")
def mobile_base_task():
    """The mobile robot with its base link as the only end effector."""
    return load_robot("sda10f_dual_mobile", ee_frames=("mobile_base",))


def around_home(robot, rng: np.random.Generator, spread: float = 0.3) -> np.ndarray:
    """``q_home`` moved by a random velocity for 1 s (any joint, the planar one included)."""
    return pin.integrate(robot.model, robot.q_home, rng.uniform(-spread, spread, robot.model.nv))


def with_base(robot, q: np.ndarray, x: float, y: float, heading: float) -> np.ndarray:
    """``q`` with the planar base at ``(x, y)``, heading ``heading``."""
    q = q.copy()
    q[:4] = x, y, math.cos(heading), math.sin(heading)
    return q


def stacked_ee_jacobian(robot, data: pin.Data) -> np.ndarray:
    return np.vstack([pin.getFrameJacobian(robot.model, data, frame, pin.LOCAL)
                      for frame in robot.ee_frame_ids])


def hole_rows(robot, data: pin.Data, holes: list[Hole]) -> tuple[np.ndarray, np.ndarray]:
    rows = [hole.rows(robot.model, data, robot.model.getFrameId(hole.link)) for hole in holes]
    return np.vstack([A for A, _ in rows]), np.concatenate([b for _, b in rows])


def consistent_twist(robot, q: np.ndarray, holes: list[Hole], rng: np.random.Generator,
                     speed: float) -> tuple[np.ndarray, float]:
    """A stacked twist both EEs can meet with the holes held (``J_e qd0``, ``A qd0 = 0``,
    ``max |qd0| = speed``), and the smallest singular value of ``J_e`` on ``null(A)``."""
    data = kinematics(robot, q)
    A, _ = hole_rows(robot, data, holes)
    null = scipy.linalg.null_space(A)
    qd0 = null @ rng.normal(size=null.shape[1])
    qd0 *= speed / np.abs(qd0).max()
    jacobian = stacked_ee_jacobian(robot, data)
    return jacobian @ qd0, float(np.linalg.svd(jacobian @ null, compute_uv=False)[-1])


def check_agreement(robot, q: np.ndarray, holes: list[Hole], twist: np.ndarray,
                    agreement: float, posture: np.ndarray) -> None:
    """mink's ``qd`` is the CJM's and the QP's, holds the holes and meets both twists."""
    cjm = CJMController(robot, holes, posture=posture, **EXACT_CJM)
    # the QP and mink carry the CJM's damping (docs/design.md 10.7): undamped as it is here
    qp = QPController(robot, holes, solver="daqp", posture=posture, **EXACT_CJM)
    mink = MinkController(robot, holes, posture=posture, **EXACT_CJM)
    qd_cjm, qd_qp, qd = cjm.solve(q, twist), qp.solve(q, twist), mink.solve(q, twist)
    for controller in (cjm, qp, mink):
        assert controller.info.status is StepStatus.OK, controller.info.message
    np.testing.assert_allclose(qd, qd_cjm, rtol=0.0, atol=agreement)
    np.testing.assert_allclose(qd, qd_qp, rtol=0.0, atol=agreement)
    data = kinematics(robot, q)
    A, b = hole_rows(robot, data, holes)
    assert np.abs(A @ qd - b).max() <= 1e-9
    assert mink.info.equality_residual <= 1e-9
    np.testing.assert_allclose(stacked_ee_jacobian(robot, data) @ qd, twist, rtol=0.0, atol=1e-7)


# ----------------------------------------------------------------------------- two arms


@PROPERTY
@given(seed=SEEDS, speed=st.floats(0.01, 0.3))
def test_two_arms_through_two_trocars_agree_with_the_cjm_and_the_qp(dual, seed, speed):
    """sda10f_dual, a hole on each arm's link, a twist consistent with both holes."""
    rng = np.random.default_rng(seed)
    q = around_home(dual, rng)
    holes = [Hole.on_link(dual, q, HOLE_DISTANCE, link=link) for link in dual.constrained_links]
    twist, sigma_min = consistent_twist(dual, q, holes, rng, speed)
    assume(sigma_min > 1e-3)  # the stacked CJM is non-singular
    check_agreement(dual, q, holes, twist, TWO_ARM_AGREEMENT, dual.q_home)


def test_each_frame_task_gets_its_own_slice_of_the_twist(dual):
    """Target of EE ``i``: ``T_ei exp6(V_i dt)``, ``V_i`` entries ``6 i .. 6 i + 5``."""
    q = dual.q_home.copy()
    controller = MinkController(dual, dt=2e-3)
    twist = np.arange(1.0, 13.0) / 100.0
    controller.solve(q, twist)
    data = kinematics(dual, q)
    assert [task.frame_name for task in controller.ee_tasks] == [
        site_name(frame) for frame in dual.ee_frames]
    for index, (task, frame) in enumerate(zip(controller.ee_tasks, dual.ee_frame_ids)):
        expected = data.oMf[frame] * pin.exp6(twist[6 * index:6 * index + 6] * 2e-3)
        np.testing.assert_allclose(task.transform_target_to_world.as_matrix(),
                                   expected.homogeneous, atol=1e-12)


def test_posture_scale_is_the_mean_squared_singular_value_of_the_stacked_task(dual):
    """``c = posture_cost sqrt(s)``, ``s = |J_e|_F^2 / 12``: the mean of ``sigma_i^2``."""
    q = dual.q_home.copy()
    controller = MinkController(dual)
    controller.solve(q, np.zeros(12))
    sigma = np.linalg.svd(stacked_ee_jacobian(dual, kinematics(dual, q)), compute_uv=False)
    scale = float(np.sum(sigma**2)) / 12
    np.testing.assert_allclose(controller.posture_task.cost,
                               controller.posture_cost * math.sqrt(scale), rtol=1e-12)


# ----------------------------------------------------------------------------- mobile base


@PROPERTY
@given(seed=SEEDS, x=st.floats(-3.0, 3.0), y=st.floats(-3.0, 3.0), heading=HEADINGS)
def test_joint_map_round_trips_a_planar_base(mobile, mobile_controller, seed, x, y, heading):
    """Configurations and velocities survive Pinocchio -> MuJoCo -> Pinocchio; a matrix on
    Pinocchio velocities and its MuJoCo columns give the same product."""
    rng = np.random.default_rng(seed)
    joints = mobile_controller.joints
    q = with_base(mobile, around_home(mobile, rng), x, y, heading)
    q_mj = joints.q_to_mujoco(q, out=np.empty(mobile.nq - 1))
    assert q_mj[2] == pytest.approx(heading, abs=1e-12)
    np.testing.assert_allclose(joints.q_to_pinocchio(q_mj, out=np.empty(mobile.nq)), q,
                               rtol=0.0, atol=1e-15)
    v = rng.normal(size=mobile.nv)
    v_mj = joints.v_to_mujoco(v, q_mj)
    c, s = math.cos(heading), math.sin(heading)
    np.testing.assert_allclose(v_mj[:2], [c * v[0] - s * v[1], s * v[0] + c * v[1]], atol=1e-15)
    np.testing.assert_allclose(joints.v_to_pinocchio(v_mj, q_mj), v, rtol=0.0, atol=1e-15)
    matrix = rng.normal(size=(4, mobile.nv))
    np.testing.assert_allclose(joints.columns_to_mujoco(matrix, q_mj) @ v_mj, matrix @ v,
                               rtol=0.0, atol=1e-13)


def mujoco_site_pose(controller: MinkController, q: np.ndarray, frame: str) -> pin.SE3:
    controller.configuration.update(
        controller.joints.q_to_mujoco(q, out=np.empty(controller.mj_model.nq)))
    return controller.site_pose(frame)


@PROPERTY
@given(seed=SEEDS, heading=HEADINGS)
def test_mujoco_jacobian_columns_are_pinocchios_local_jacobian(mobile, mobile_controller, seed,
                                                               heading):
    """For each EE site: MuJoCo's LOCAL Jacobian (mink's, world-frame base slides) mapped
    to Pinocchio's columns equals finite differences of MuJoCo's site pose along
    ``pin.integrate(q, eps e_k)`` and Pinocchio's own LOCAL frame Jacobian."""
    rng = np.random.default_rng(seed)
    controller = mobile_controller
    q = with_base(mobile, around_home(mobile, rng), *rng.uniform(-2.0, 2.0, 2), heading)
    data = kinematics(mobile, q)
    eps = 1e-6
    for frame, frame_id in zip(mobile.ee_frames, mobile.ee_frame_ids):
        differences = np.empty((6, mobile.nv))
        for k in range(mobile.nv):
            step = np.zeros(mobile.nv)
            step[k] = eps
            plus = mujoco_site_pose(controller, pin.integrate(mobile.model, q, step), frame)
            minus = mujoco_site_pose(controller, pin.integrate(mobile.model, q, -step), frame)
            differences[:, k] = pin.log6(minus.actInv(plus)).vector / (2 * eps)
        pose = mujoco_site_pose(controller, q, frame)
        np.testing.assert_allclose(pose.homogeneous, data.oMf[frame_id].homogeneous, atol=1e-12)
        q_mj = controller.configuration.q
        jacobian_mj = controller.configuration.get_frame_jacobian(site_name(frame), "site")
        to_mujoco = np.column_stack([controller.joints.v_to_mujoco(e, q_mj)
                                     for e in np.eye(mobile.nv)])
        jacobian_pin = pin.getFrameJacobian(mobile.model, data, frame_id, pin.LOCAL)
        np.testing.assert_allclose(jacobian_mj @ to_mujoco, differences, rtol=0.0, atol=1e-8)
        np.testing.assert_allclose(jacobian_mj @ to_mujoco, jacobian_pin, rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(controller.joints.columns_to_mujoco(jacobian_pin, q_mj),
                                   jacobian_mj, rtol=0.0, atol=1e-12)


@PROPERTY
@given(seed=SEEDS, heading=HEADINGS, speed=st.floats(0.01, 0.3))
def test_mobile_robot_through_two_trocars_agrees_with_the_cjm_and_the_qp(mobile, seed, heading,
                                                                           speed):
    """sda10f_dual_mobile, base anywhere, a hole on each arm, a consistent twist.

    The posture is ``q_home``'s arms on a base pose ``q_base exp(xi)``, ``|xi| <= 0.3``:
    a posture velocity inside the box, whose base part ``xi`` (Pinocchio's SE(2)
    logarithm, in the base frame) is not MuJoCo's world-frame ``(dx, dy, dth)``. (Pulled
    back towards a base pose metres away, the posture asks for more than the base's
    limits; the CJM's saturation then spends the 2 free directions its own way, away from
    the QP's and mink's box-constrained closest point.)
    """
    rng = np.random.default_rng(seed)
    q = with_base(mobile, around_home(mobile, rng), *rng.uniform(-2.0, 2.0, 2), heading)
    holes = [Hole.on_link(mobile, q, HOLE_DISTANCE, link=link)
             for link in mobile.constrained_links]
    twist, sigma_min = consistent_twist(mobile, q, holes, rng, speed)
    assume(sigma_min > 1e-3)
    base_offset = np.zeros(mobile.nv)
    base_offset[:3] = rng.uniform(-0.3, 0.3, 3)
    posture = mobile.q_home.copy()
    posture[:4] = pin.integrate(mobile.model, q, base_offset)[:4]
    check_agreement(mobile, q, holes, twist, MOBILE_AGREEMENT, posture)

@PROPERTY
@given(seed=SEEDS, heading=HEADINGS, vx=st.floats(-0.45, 0.45), vy=st.floats(-0.45, 0.45),
       w=st.floats(-0.9, 0.9))
def test_pure_base_motion_is_the_cjms_and_the_qps(mobile_base_task, seed, heading, vx, vy, w):
    """The base link as the EE, a planar twist ``(v_x, v_y, 0, 0, 0, w)`` inside the base's
    limits: every controller drives the base at exactly that (base-frame) velocity, with
    the arms on their posture; mink's answer, mapped from world-frame slides, is theirs."""
    robot = mobile_base_task
    rng = np.random.default_rng(seed)
    q = with_base(robot, around_home(robot, rng), *rng.uniform(-2.0, 2.0, 2), heading)
    twist = np.array([vx, vy, 0.0, 0.0, 0.0, w])
    cjm = CJMController(robot, **EXACT_CJM)
    qp = QPController(robot, solver="daqp")
    mink = MinkController(robot)
    qd = mink.solve(q, twist)
    assert mink.info.status is StepStatus.OK, mink.info.message
    np.testing.assert_allclose(qd[:3], [vx, vy, w], rtol=0.0, atol=BASE_AGREEMENT)
    np.testing.assert_allclose(qd, cjm.solve(q, twist), rtol=0.0, atol=BASE_AGREEMENT)
    np.testing.assert_allclose(qd, qp.solve(q, twist), rtol=0.0, atol=BASE_AGREEMENT)
    # the arms follow the posture, as the CJM's qd_posture = pin.difference(q, q_home)
    np.testing.assert_allclose(qd[3:], pin.difference(robot.model, q, robot.q_home)[3:],
                               rtol=0.0, atol=BASE_AGREEMENT)


@PROPERTY
@given(seed=SEEDS, heading=HEADINGS)
def test_posture_of_the_base_is_pinocchios_difference(mobile_left_arm, seed, heading):
    """One EE (12 free directions, the base among them), the posture's base ``exp(xi)``
    away: mink's posture velocity is the CJM's ``pin.difference`` (the SE(2) logarithm in
    the base frame), not MuJoCo's world-frame ``(dx, dy, dth)``, which differ by
    ``O(|dth| |dp|)``, up to 0.05 here."""
    robot = mobile_left_arm
    rng = np.random.default_rng(seed)
    q = with_base(robot, around_home(robot, rng), *rng.uniform(-2.0, 2.0, 2), heading)
    base_offset = np.zeros(robot.nv)
    base_offset[:3] = rng.uniform(-0.3, 0.3, 3)
    posture = robot.q_home.copy()
    posture[:4] = pin.integrate(robot.model, q, base_offset)[:4]
    twist = 0.05 * rng.normal(size=6)
    qd_cjm = CJMController(robot, posture=posture, **EXACT_CJM).solve(q, twist)
    qd_qp = QPController(robot, solver="daqp", posture=posture).solve(q, twist)
    mink = MinkController(robot, posture=posture)
    qd = mink.solve(q, twist)
    assert mink.info.status is StepStatus.OK, mink.info.message
    np.testing.assert_allclose(qd, qd_cjm, rtol=0.0, atol=MOBILE_AGREEMENT)
    np.testing.assert_allclose(qd, qd_qp, rtol=0.0, atol=MOBILE_AGREEMENT)


@PROPERTY
@given(seed=SEEDS, heading=HEADINGS, direction=st.floats(-math.pi, math.pi),
       speed=st.floats(0.8, 2.0))
def test_base_velocity_limit_binds_pinocchios_base_frame_velocity(mobile_base_task, seed,
                                                                  heading, direction, speed):
    """A base twist beyond ``velocityLimit[:3]`` (0.5 m/s, 0.5 m/s, 1 rad/s, base frame):
    mink's command is inside ``joint_bounds.box(q)`` without the base class clipping it
    (no ``constraint_degraded``) and at a limit, and it is the QP's least-squares answer up
    to mink's metric ``Jr^-1(-V dt) = I + O(|V| dt)`` on the residual."""
    robot = mobile_base_task
    rng = np.random.default_rng(seed)
    q = with_base(robot, around_home(robot, rng), *rng.uniform(-2.0, 2.0, 2), heading)
    twist = np.array([speed * math.cos(direction), speed * math.sin(direction), 0.0, 0.0, 0.0,
                      rng.uniform(-2.0, 2.0)])
    mink = MinkController(robot)
    qd = mink.solve(q, twist)
    assert mink.info.status is StepStatus.LEAST_SQUARES, mink.info.message
    lower, upper = mink.joint_bounds.box(q)
    limit = robot.model.velocityLimit[:3]
    slack = 1e-9 * limit
    assert np.all(qd[:3] >= lower[:3] - slack) and np.all(qd[:3] <= upper[:3] + slack)
    assert np.all(qd >= lower - 1e-9) and np.all(qd <= upper + 1e-9)
    assert np.max(np.abs(qd[:3]) / limit) == pytest.approx(1.0, abs=1e-9)
    qp = QPController(robot, solver="daqp")
    qd_qp = qp.solve(q, twist)
    residual = float(np.linalg.norm(ee_residual(robot, q, qd_qp, twist)))
    bound = np.linalg.norm(twist) * mink.dt * residual
    assert np.abs(qd - qd_qp).max() <= bound


def ee_residual(robot, q: np.ndarray, qd: np.ndarray, twist: np.ndarray) -> np.ndarray:
    return stacked_ee_jacobian(robot, kinematics(robot, q)) @ qd - twist


@PROPERTY
@given(seed=SEEDS, heading=HEADINGS)
def test_sites_follow_pinocchio_on_the_planar_base(mobile, mobile_controller, seed, heading):
    """Every site (the base link, both EEs, both trocar links) sits at ``oMf``."""
    rng = np.random.default_rng(seed)
    q = with_base(mobile, around_home(mobile, rng), *rng.uniform(-3.0, 3.0, 2), heading)
    mobile_controller.solve(q, np.zeros(12))
    data = kinematics(mobile, q)
    for frame in ("mobile_base", *mobile.ee_frames, *mobile.constrained_links):
        np.testing.assert_allclose(mobile_controller.site_pose(frame).homogeneous,
                                   data.oMf[mobile.model.getFrameId(frame)].homogeneous,
                                   atol=1e-12, err_msg=frame)


def test_weighted_task_matches_the_cjm_and_the_qp():
    """``twist_weight`` on the two-trocar robot, tips' linear velocities only: mink's frame
    tasks with those costs give the CJM's and the QP's command (the rest to the posture,
    which mink weights where the others put it last: the bound of the mobile test)."""
    robot = load_robot("sda10f_dual")
    weight = [1.0, 1.0, 1.0, 0.0, 0.0, 0.0]
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = pin.integrate(robot.model, robot.q_home, rng.uniform(-0.1, 0.1, robot.model.nv))
        holes = [Hole.on_link(robot, q, distance=0.08, link=link) for link in robot.constrained_links]
        twist = rng.normal(scale=0.01, size=12)
        qd_cjm = CJMController(robot, holes, twist_weight=weight).solve(q, twist)
        qd_qp = QPController(robot, holes, solver="daqp", twist_weight=weight).solve(q, twist)
        mink_controller = MinkController(robot, holes, twist_weight=weight)
        qd_mink = mink_controller.solve(q, twist)
        assert mink_controller.info.status.value == "ok", mink_controller.info.message
        np.testing.assert_allclose(qd_cjm, qd_qp, atol=1e-6)
        np.testing.assert_allclose(qd_mink, qd_cjm, atol=1e-4)
