"""Whole-body robots (docs/design.md section 11): two end effectors through two trocars on one
torso, and the same robot on a planar mobile base.

References independent of the controllers: Pinocchio's frame velocities, finite differences
through ``pin.integrate`` (the planar joint's configuration is not its velocity), and an
orthonormal null-space solution written here with SciPy.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from conftest import kinematics, near_home

from constraints import Barrier, Hole
from controllers import CJMController, QPController

HOLE_DISTANCE = 0.08
SEEDS = st.integers(0, 2**32 - 1)
PROPERTY = settings(max_examples=25, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


def holes_on_both_arms(robot, q: np.ndarray) -> list[Hole]:
    return [Hole.on_link(robot, q, distance=HOLE_DISTANCE, link=link)
            for link in robot.constrained_links]


def stacked_ee_jacobian(robot, q: np.ndarray) -> np.ndarray:
    data = kinematics(robot, q)
    return np.vstack([pin.getFrameJacobian(robot.model, data, frame, pin.LOCAL)
                      for frame in robot.ee_frame_ids])


def hole_rows(robot, q: np.ndarray, holes: list[Hole]) -> tuple[np.ndarray, np.ndarray]:
    data = kinematics(robot, q)
    blocks = [hole.rows(robot.model, data) for hole in holes]
    return np.vstack([A for A, _ in blocks]), np.concatenate([b for _, b in blocks])


def lateral_velocity(robot, q: np.ndarray, qd: np.ndarray, hole: Hole) -> float:
    """Speed of the shaft's material point at the hole across the shaft (Pinocchio's
    frame velocity, not the constraint's rows)."""
    model, data = robot.model, robot.model.createData()
    pin.forwardKinematics(model, data, q, qd)
    pin.updateFramePlacements(model, data)
    frame = model.getFrameId(hole.link)
    placement = data.oMf[frame]
    point = hole.evaluate(placement).p  # the point of the shaft at the hole, link coordinates
    velocity = pin.getFrameVelocity(model, data, frame, pin.LOCAL)
    point_velocity = velocity.linear + np.cross(velocity.angular, point)
    across = point_velocity - (point_velocity @ hole.link_axis) * hole.link_axis
    return float(np.linalg.norm(across))


def test_dual_robot_declares_both_arms(dual):
    assert dual.model.nq == dual.model.nv == 15
    assert len(dual.ee_frames) == 2 and dual.task_size == 12
    assert len(dual.constrained_links) == 2
    data = kinematics(dual, dual.q_home)
    for link in dual.constrained_links:  # each axis points from joint R towards the tool
        placement = data.oMf[dual.model.getFrameId(link)]
        tool = [data.oMf[f].translation for f in dual.ee_frame_ids
                if dual.model.frames[f].name.split("_")[1] == link.split("_")[1]][0]
        axis_world = placement.rotation @ dual.link_axes[link]
        assert axis_world @ (tool - placement.translation) > 0.1


@PROPERTY
@given(seed=SEEDS)
def test_cjm_and_qp_agree_with_a_hole_on_each_arm(dual, seed):
    """Both holes held (lateral velocity <= 1e-10 m/s from Pinocchio), and the CJM's command
    equals the QP's where no limit binds: the same least-squares problem (11 free joint
    directions for a 12-entry task, docs/design.md section 11.2)."""
    rng = np.random.default_rng(seed)
    q = near_home(dual, rng)
    holes = holes_on_both_arms(dual, q)
    twist = np.concatenate([rng.normal(scale=0.01, size=6) for _ in dual.ee_frames])
    cjm = CJMController(dual, holes)
    qd_cjm = cjm.solve(q, twist)
    assume(cjm.info.method == "general" and cjm.info.damping == 0.0)  # no limit, no DLS
    assert cjm.info.status.value in ("ok", "least_squares"), cjm.info.message
    for solver in ("proxqp", "daqp"):
        qp = QPController(dual, holes, solver=solver)
        qd_qp = qp.solve(q, twist)
        assert qp.info.status.value in ("ok", "least_squares"), qp.info.message
        np.testing.assert_allclose(qd_qp, qd_cjm, atol=1e-6, err_msg=solver)
        for hole in holes:
            assert lateral_velocity(dual, q, qd_qp, hole) <= 1e-10
    for hole in holes:
        assert lateral_velocity(dual, q, qd_cjm, hole) <= 1e-10


@PROPERTY
@given(seed=SEEDS)
def test_least_squares_command_is_the_null_space_solution(dual, seed):
    """The CJM's command against a least-squares solution over null(A) written here."""
    rng = np.random.default_rng(seed)
    q = near_home(dual, rng)
    holes = holes_on_both_arms(dual, q)
    twist = rng.normal(scale=0.05, size=12)
    cjm = CJMController(dual, holes, posture_gain=0.0, position_limits=False,
                        velocity_limits=False)
    qd = cjm.solve(q, twist)
    assume(cjm.info.damping == 0.0)  # the reference is undamped
    rows, rhs = hole_rows(dual, q, holes)
    null_basis = scipy.linalg.null_space(rows)
    assert null_basis.shape[1] == 11  # 15 joints, 4 rows
    particular = np.linalg.lstsq(rows, rhs, rcond=None)[0]
    jacobian = stacked_ee_jacobian(dual, q)
    y = np.linalg.lstsq(jacobian @ null_basis, twist - jacobian @ particular, rcond=None)[0]
    np.testing.assert_allclose(qd, particular + null_basis @ y, atol=1e-9)


@PROPERTY
@given(seed=SEEDS)
def test_twists_consistent_with_the_holes_are_met_exactly(dual, seed):
    """Twists the holes allow (``J qd`` of a ``qd`` that holds them) are met exactly by
    both controllers, for both EEs, with status ok."""
    rng = np.random.default_rng(seed)
    q = near_home(dual, rng)
    holes = holes_on_both_arms(dual, q)
    rows, rhs = hole_rows(dual, q, holes)
    feasible = (np.linalg.lstsq(rows, rhs, rcond=None)[0]
                + scipy.linalg.null_space(rows) @ rng.normal(scale=0.1, size=11))
    jacobian = stacked_ee_jacobian(dual, q)
    twist = jacobian @ feasible
    for controller in (CJMController(dual, holes), QPController(dual, holes, solver="daqp")):
        qd = controller.solve(q, twist)
        assert controller.info.status.value == "ok", controller.info.message
        np.testing.assert_allclose(jacobian @ qd, twist, atol=1e-9)
        np.testing.assert_allclose(qd, feasible, atol=1e-8)


def test_twist_of_the_wrong_size_is_refused(dual):
    controller = CJMController(dual, holes_on_both_arms(dual, dual.q_home))
    with pytest.raises(ValueError, match="twist"):
        controller.solve(dual.q_home, np.zeros(6))


# -- the mobile base ----------------------------------------------------------------------


def test_mobile_robot_is_the_dual_robot_on_a_planar_base(mobile, dual):
    assert (mobile.model.nq, mobile.model.nv) == (19, 18)
    assert mobile.root_joint == "planar"
    np.testing.assert_array_equal(mobile.model.velocityLimit[:3] > 0, True)
    assert np.all(np.isfinite(mobile.model.velocityLimit))
    data, dual_data = kinematics(mobile, mobile.q_home), kinematics(dual, dual.q_home)
    base = data.oMf[mobile.model.getFrameId("mobile_base")]
    for frame in dual.ee_frames:  # the arm rides the base rigidly
        relative = base.actInv(data.oMf[mobile.model.getFrameId(frame)])
        dual_relative = dual_data.oMf[dual.model.getFrameId("base_link")].actInv(
            dual_data.oMf[dual.model.getFrameId(frame)])
        np.testing.assert_allclose(relative.rotation, dual_relative.rotation, atol=1e-12)


@PROPERTY
@given(seed=SEEDS, heading=st.floats(-np.pi, np.pi))
def test_mobile_jacobians_and_rows_match_finite_differences(mobile, seed, heading):
    """EE Jacobians and hole rows against central differences through ``pin.integrate``."""
    rng = np.random.default_rng(seed)
    q = near_home(mobile, rng)
    q[2:4] = np.cos(heading), np.sin(heading)
    holes = holes_on_both_arms(mobile, q)
    qd = rng.normal(size=mobile.model.nv)
    step = 1e-6
    q_plus = pin.integrate(mobile.model, q, step * qd)
    q_minus = pin.integrate(mobile.model, q, -step * qd)
    data_plus, data_minus = kinematics(mobile, q_plus), kinematics(mobile, q_minus)
    jacobian = stacked_ee_jacobian(mobile, q)
    for i, frame in enumerate(mobile.ee_frame_ids):
        twist = pin.log6(data_minus.oMf[frame].actInv(data_plus.oMf[frame])).vector / (2 * step)
        # log6 of the relative motion over 2 steps is the body twist at the midpoint, q
        np.testing.assert_allclose(jacobian[6 * i:6 * i + 6] @ qd, twist, atol=1e-6)
    rows, _ = hole_rows(mobile, q, holes)
    errors_plus = np.concatenate([h.error(data_plus.oMf[mobile.model.getFrameId(h.link)])
                                  for h in holes])
    errors_minus = np.concatenate([h.error(data_minus.oMf[mobile.model.getFrameId(h.link)])
                                   for h in holes])
    np.testing.assert_allclose(rows @ qd, (errors_plus - errors_minus) / (2 * step), atol=1e-6)


@pytest.mark.slow
def test_a_barrier_on_the_base_is_never_crossed(mobile):
    """Both EEs asked to drive through a wall for 3 s: the base's corner stops at the wall
    and slides along it while the base turns. The barrier row holds at every step; the
    only penetration is the first-order rows' discretisation (docs/design.md section
    11.3): each step the corner's true rate (finite differences through ``pin.integrate``)
    differs from the row's ``A qd`` by ``|a| dt / 2``, which the barrier's feedback
    ``-K d`` balances at a depth of at most that difference over ``K``."""
    q = mobile.q_home.copy()
    base_frame = mobile.model.getFrameId("mobile_base")
    corner = np.array([0.4, 0.3, 0.0])  # link coordinates of a corner of the base
    wall_x = float(kinematics(mobile, q).oMf[base_frame].act(corner)[0]) + 0.10
    wall = Barrier("mobile_base", corner, [wall_x, 0.0, 0.0], [-1.0, 0.0, 0.0])
    for controller in (CJMController(mobile, [wall]), QPController(mobile, [wall], solver="daqp")):
        q = mobile.q_home.copy()
        depth, worst_rate_miss = 0.0, 0.0
        distance = wall_x - float(kinematics(mobile, q).oMf[base_frame].act(corner)[0])
        for _ in range(3000):
            data = kinematics(mobile, q)
            # both EEs pushed along world +x at 0.3 m/s, expressed in each EE's frame
            twist = np.concatenate([
                np.concatenate([data.oMf[f].rotation.T @ [0.3, 0.0, 0.0], np.zeros(3)])
                for f in mobile.ee_frame_ids])
            qd = controller.solve(q, twist)
            assert controller.info.success
            rows, bound = wall.rows(mobile.model, data)
            assert rows[0] @ qd >= bound[0] - 1e-9  # the barrier row held
            q = pin.integrate(mobile.model, q, qd * controller.dt)
            new_distance = wall_x - float(kinematics(mobile, q).oMf[base_frame].act(corner)[0])
            rate_miss = rows[0] @ qd - (new_distance - distance) / controller.dt
            worst_rate_miss = max(worst_rate_miss, rate_miss)
            distance = new_distance
            depth = max(depth, -distance)
        name = type(controller).__name__
        assert distance < 1e-3, f"{name}: the base never reached the wall ({distance:.3f} m)"
        assert worst_rate_miss < 2e-4, name  # |a| dt / 2 with |a| ~ 0.2 m/s^2
        assert depth <= 1.01 * worst_rate_miss / wall.gain + 1e-12, (name, depth)


@PROPERTY
@given(seed=SEEDS, magnitude=st.sampled_from([1e-3, 0.1, 10.0, 1e4]),
       robot_name=st.sampled_from(["sda10f_dual", "sda10f_dual_mobile"]))
def test_commands_stay_inside_the_joint_box(dual, mobile, seed, magnitude, robot_name):
    """Configurations near the position limits, twists from 1 mm/s to 10 km/s: every
    command is finite and inside the box; the holes are held unless the step says so."""
    robot = dual if robot_name == "sda10f_dual" else mobile
    rng = np.random.default_rng(seed)
    q = robot.random_configuration(rng, margin=0.0)
    bounded = np.abs(robot.model.lowerPositionLimit) < 1e10
    near_limit = bounded & (rng.uniform(size=robot.model.nq) < 0.3)
    q[near_limit] = np.where(rng.uniform(size=near_limit.sum()) < 0.5,
                             robot.model.lowerPositionLimit[near_limit] + 1e-4,
                             robot.model.upperPositionLimit[near_limit] - 1e-4)
    holes = holes_on_both_arms(robot, q)
    twist = rng.normal(scale=magnitude, size=robot.task_size)
    for controller in (CJMController(robot, holes), QPController(robot, holes, solver="daqp")):
        qd = controller.solve(q, twist)
        lower, upper = controller.bounds(q)
        assert np.all(np.isfinite(qd))
        assert np.all(qd >= lower - 1e-9 * (1 + np.abs(lower)))
        assert np.all(qd <= upper + 1e-9 * (1 + np.abs(upper)))
        if controller.info.status.value != "constraint_degraded":
            rows, rhs = hole_rows(robot, q, holes)
            assert np.max(np.abs(rows @ qd - rhs)) <= 1e-9, type(controller).__name__


@PROPERTY
@given(seed=SEEDS, positions_only=st.booleans())
def test_weighted_twists_cjm_equals_qp(dual, seed, positions_only):
    """``twist_weight``: the CJM's weighted general form is the QP's weighted task. With
    the tips' linear velocities only (orientation weight 0), both tips are met exactly
    (6 entries for 11 free joint directions) and the rest goes to the posture in both."""
    rng = np.random.default_rng(seed)
    q = near_home(dual, rng)
    holes = holes_on_both_arms(dual, q)
    twist = rng.normal(scale=0.01, size=12)
    weight = [1.0, 1.0, 1.0, 0.0, 0.0, 0.0] if positions_only else rng.uniform(0.1, 2.0, 12)
    cjm = CJMController(dual, holes, twist_weight=weight)
    qd_cjm = cjm.solve(q, twist)
    assume(cjm.info.method == "general" and cjm.info.damping == 0.0)
    qp = QPController(dual, holes, solver="daqp", twist_weight=weight)
    qd_qp = qp.solve(q, twist)
    np.testing.assert_allclose(qd_qp, qd_cjm, atol=1e-6)
    if positions_only:
        linear = stacked_ee_jacobian(dual, q)[[0, 1, 2, 6, 7, 8]]
        np.testing.assert_allclose(linear @ qd_cjm, twist[[0, 1, 2, 6, 7, 8]], atol=1e-9)
        assert cjm.info.status.value == "ok", cjm.info.message


def test_twist_weight_is_checked(dual):
    holes = holes_on_both_arms(dual, dual.q_home)
    for bad in ([1.0] * 5, [-1.0] * 6, [np.nan] * 12):
        with pytest.raises(ValueError, match="twist_weight"):
            CJMController(dual, holes, twist_weight=bad)
