"""MinkController, the outside peer: the same constrained step posed to mink.

Real solvers, no mocks. What is checked:

* the MuJoCo model compiled from the robot's URDF (sites added through ``MjSpec``) has the
  kinematics of the Pinocchio model: same joints, same frame poses;
* mink's hard constraint task is exactly our ``A qd = b`` and the EE frame task tracks
  the twist: with a hole, mink's ``qd`` equals the exact CJM's;
* solver failures (infeasible equalities) give the flagged zero command;
* a barrier held against a push agrees with the QP controller.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from conftest import HOLE_DISTANCE, ee_jacobian, kinematics, near_home

from constraints import Barrier, Hole, PointLock
from controllers import CJMController, MinkController, QPController, SolverError, StepStatus
from controllers.mujoco_model import JointMap, site_name
from teleop import load_robot

EXACT = dict(singular_threshold=0.0, velocity_limits=False, position_limits=False)  # undamped, unscaled CJM

#: mink vs the exact CJM with a hole (rad/s). Measured: 2e-12 to 3e-8 on the built-in
#: robots, for daqp, proxqp and osqp alike. The floor is not a solver tolerance nor the
#: damping: it is mink 1.3.0's SE(3) ``jlog`` (``mink/lie/se3.py::_getQ``), which
#: evaluates ``C = (1 - t^2/2 - cos t) / t^4`` and ``D`` in closed form as soon as
#: ``t^2`` exceeds machine epsilon; at ``t = |w| dt ~ 1e-5`` rad the cancellation leaves
#: ``Jlog`` wrong by ~1e-7 (8e-8 against Pinocchio's ``Jlog6``), i.e. ``J_e qd`` off the
#: twist by ~6e-10 m/s. Swapping in Pinocchio's ``Jlog6`` brings the agreement to
#: 4e-12..1e-9 (the rest is mink's ``damping = 1e-12``). Well inside the 1e-6 asked for.
AGREEMENT = 1e-6


def small_twist(rng: np.random.Generator, norm: float = 0.02) -> np.ndarray:
    twist = rng.normal(size=6)
    return norm * twist / np.linalg.norm(twist)


# ----------------------------------------------------------------------------- model


def test_joints_are_matched_by_name(robot):
    controller = MinkController(robot)
    pin_names = [robot.model.names[j] for j in range(1, robot.model.njoints)]
    assert list(controller.joints.names) == pin_names
    assert len(pin_names) == 8
    mj = controller.mj_model
    assert [mj.joint(name).type for name in pin_names] == [mujoco_hinge()] * 8
    assert controller.joints.identity  # same tree order in both models for these URDFs


def mujoco_hinge():
    import mujoco

    return mujoco.mjtJoint.mjJNT_HINGE


@pytest.mark.parametrize("seed", range(3))
def test_mujoco_sites_match_pinocchio_forward_kinematics(robot, seed):
    """Every added site (EE, every link incl. the constrained one) sits at ``oMf``."""
    rng = np.random.default_rng(seed)
    controller = MinkController(robot)
    frames = set(controller.site_names)
    assert {robot.ee_frame, robot.constrained_link} <= frames
    for _ in range(10):
        q = robot.random_configuration(rng)
        controller.solve(q, np.zeros(6))  # no constraint: always feasible
        data = kinematics(robot, q)
        for frame in frames:
            expected = data.oMf[robot.model.getFrameId(frame)]
            np.testing.assert_allclose(controller.site_pose(frame).homogeneous,
                                       expected.homogeneous, atol=1e-9, err_msg=frame)


def test_mujoco_site_jacobian_matches_pinocchio(robot):
    rng = np.random.default_rng(7)
    controller = MinkController(robot)
    q = near_home(robot, rng)
    controller.solve(q, np.zeros(6))
    jacobian = controller.configuration.get_frame_jacobian(site_name(robot.ee_frame), "site")
    np.testing.assert_allclose(jacobian, ee_jacobian(robot, q), atol=1e-12)


def test_urdf_meshes_are_not_needed(tmp_path):
    """MuJoCo only gets the kinematics: a URDF whose meshes are missing still compiles."""
    source = load_robot("ur5_instrument").urdf_path.read_text()
    broken = source.replace(
        "<link name=\"flange\"/>",
        "<link name=\"flange\"><visual><geometry><mesh filename=\"package://nowhere/x.stl\"/>"
        "</geometry></visual></link>")
    assert broken != source
    path = tmp_path / "ur5_instrument.urdf"
    path.write_text(broken)
    with pytest.warns(UserWarning):  # Pinocchio's geometry loader misses the mesh
        robot = load_robot(path, ee_frame="tool_tip", constrained_link="instrument_shaft")
    controller = MinkController(robot)
    assert controller.solve(np.zeros(8), np.zeros(6)).shape == (8,)
    assert controller.info.success


def test_joint_map_permutes_both_ways():
    joints = JointMap(("a", "b", "c"), pin_q=np.array([0, 1, 2]), pin_v=np.array([0, 1, 2]),
                      mj_q=np.array([2, 0, 1]), mj_v=np.array([2, 0, 1]), identity=False)
    q_pin = np.array([10.0, 20.0, 30.0])
    q_mj = joints.q_to_mujoco(q_pin, out=np.empty(3))
    assert q_mj.tolist() == [20.0, 30.0, 10.0]
    assert joints.q_to_pinocchio(q_mj, out=np.empty(3)).tolist() == q_pin.tolist()
    assert joints.v_to_pinocchio(q_mj, q_mj).tolist() == q_pin.tolist()
    A_pin = np.array([[1.0, 2.0, 3.0]])
    A_mj = joints.columns_to_mujoco(A_pin, q_mj)
    assert (A_mj @ q_mj).tolist() == (A_pin @ q_pin).tolist()
    assert A_mj.tolist() == [[2.0, 3.0, 1.0]]


# ----------------------------------------------------------------------------- conventions


def test_constraint_task_is_our_rows_in_minks_units(robot):
    """mink's hard row ``J dq = -gain e`` is ``A v = b``: ``J = A``, ``e = -b dt``, gain 1."""
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    placement = kinematics(robot, q).oMf[robot.model.getFrameId(hole.link)]
    sideways = np.cross(placement.rotation @ hole.link_axis, [0.3, 0.5, 0.8])
    hole.move_to(hole.center + 1e-3 * sideways / np.linalg.norm(sideways))  # drift: b != 0
    controller = MinkController(robot, [hole], dt=2e-3)
    controller.solve(q, np.zeros(6))
    A, b = hole.rows(robot.model, kinematics(robot, q))
    assert np.abs(b).max() > 1e-2  # K e = 50 * 1 mm
    (task,) = controller.constraint_tasks
    assert task.gain == 1.0
    np.testing.assert_allclose(task.compute_jacobian(controller.configuration), A, atol=1e-15)
    np.testing.assert_allclose(-task.gain * task.compute_error(controller.configuration),
                               b * 2e-3, atol=1e-15)


def test_velocity_integrates_like_pinocchio(robot):
    """``solve`` returns a velocity (rad/s): mink's and Pinocchio's integration agree."""
    rng = np.random.default_rng(3)
    q = near_home(robot, rng)
    controller = MinkController(robot, [Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])])
    qd = controller.solve(q, small_twist(rng))
    assert controller.info.success
    np.testing.assert_allclose(controller.configuration.integrate(qd, 1e-3),
                               pin.integrate(robot.model, q, qd * 1e-3), atol=1e-15)
    # and the EE moves with the commanded body twist (the frame task's convention)
    twist = small_twist(rng)
    qd = controller.solve(q, twist)
    np.testing.assert_allclose(ee_jacobian(robot, q) @ qd, twist, atol=1e-8)


# ----------------------------------------------------------------------------- agreement


@pytest.mark.parametrize("solver", ["daqp", "proxqp"])
@pytest.mark.parametrize("seed", range(3))
def test_matches_the_exact_cjm_with_a_hole(robot, solver, seed):
    """With a hole at home and a small twist (|V| = 0.02), mink's qd is the CJM's.

    Tolerance 1e-6 rad/s; measured 2e-12 to 3e-8 (see ``AGREEMENT``: the floor is mink's
    SE(3) ``jlog``, not the solver). daqp reaches this only with its equality reduction
    (``eq_reduction=1``, the controller's default for daqp): with mink's
    ``damping = 1e-12`` the Hessian ``J^T J + 1e-12 I`` has two eigenvalues of 1e-12,
    below daqp's ``sing_tol`` (3.7e-11), and daqp's automatic proximal regularisation
    then stops 2e-5 to 3e-3 rad/s away from the solution. Equality residual <= 1e-9 m/s.
    """
    rng = np.random.default_rng(seed)
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    twist = small_twist(rng)
    expected = CJMController(robot, [hole], **EXACT).solve(q, twist)
    controller = MinkController(robot, [hole], solver=solver)
    qd = controller.solve(q, twist)
    assert controller.info.success, controller.info.message
    assert controller.info.method == f"mink:{solver}"
    np.testing.assert_allclose(qd, expected, atol=AGREEMENT)
    assert controller.info.equality_residual <= 1e-9
    A, b = hole.rows(robot.model, kinematics(robot, q))
    assert np.abs(A @ qd - b).max() <= 1e-9


@pytest.mark.parametrize("seed", range(5))
def test_matches_the_qp_controller_near_home_with_drift(robot, seed):
    """Away from home, hole pushed 1 mm sideways (drift active): mink == QP (proxqp)."""
    rng = np.random.default_rng(100 + seed)
    q = near_home(robot, rng)
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    sideways = np.cross(rng.normal(size=3), hole.center)
    hole.move_to(hole.center + 1e-3 * sideways / np.linalg.norm(sideways))
    twist = small_twist(rng)
    expected = QPController(robot, [hole], solver="proxqp").solve(q, twist)
    controller = MinkController(robot, [hole], solver="daqp")
    np.testing.assert_allclose(controller.solve(q, twist), expected, atol=AGREEMENT)
    assert controller.info.equality_residual <= 1e-9


@pytest.mark.filterwarnings("ignore::qpsolvers.warnings.SparseConversionWarning")  # mink passes dense
def test_osqp_is_reported(robot):
    """OSQP (ADMM) through mink: finite, residual <= 1e-5 m/s (printed, not hidden)."""
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=HOLE_DISTANCE[robot.name])
    twist = small_twist(np.random.default_rng(0))
    controller = MinkController(robot, [hole], solver="osqp")
    qd = controller.solve(q, twist)
    expected = CJMController(robot, [hole], **EXACT).solve(q, twist)
    print(f"{robot.name} mink:osqp equality residual {controller.info.equality_residual:.3g} m/s, "
          f"|qd - qd_cjm| = {np.abs(qd - expected).max():.3g} rad/s")
    assert controller.info.success, controller.info.message
    assert np.all(np.isfinite(qd))
    assert controller.info.equality_residual <= 1e-5
    np.testing.assert_allclose(qd, expected, atol=1e-4)


# ----------------------------------------------------------------------------- failures


#: Iteration caps of one: no backend finishes a point lock's step in them.
ONE_ITERATION = {"daqp": {"iter_limit": 1}, "proxqp": {"max_iter": 1}, "osqp": {"max_iter": 1}}


@pytest.mark.filterwarnings("ignore")  # OSQP/qpsolvers warn about the infeasible problem
@pytest.mark.parametrize("solver", ["daqp", "proxqp", "osqp"])
def test_infeasible_point_locks_are_held_at_their_least_residual(robot, solver):
    """One link point locked at two targets 1 cm apart: no velocity satisfies both; the
    least residual (docs/design.md 10.7) splits the 1 m/s conflict (K = 100 1/s), 0.5 m/s
    each, and says so."""
    q = robot.q_home.copy()
    lock = PointLock.on_link(robot, q, distance=0.05)
    other = PointLock(lock.link, lock.link_point, lock.target + [0.01, 0.0, 0.0])
    controller = MinkController(robot, [lock, other], solver=solver, time_budget=None)
    qd = controller.solve(q, np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0]))
    assert controller.info.status is StepStatus.CONSTRAINT_DEGRADED
    assert "least residual, 5.00e-01 m/s" in controller.info.message
    A, b = controller.constraint_rows([0, 1])
    assert np.max(np.abs(A @ qd - b)) == pytest.approx(0.5, abs=1e-6)
    lower, upper = controller.bounds(q)
    assert np.all(qd >= lower - 1e-9) and np.all(qd <= upper + 1e-9)


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("solver", ["daqp", "proxqp", "osqp"])
def test_a_solve_that_cannot_finish_gives_the_flagged_zero_command(robot, solver):
    """The same locks and a twist beyond every velocity limit (the box binds, so no solve
    ends at its first iterate) with every solve capped at one iteration: nothing is found."""
    q = robot.q_home.copy()
    lock = PointLock.on_link(robot, q, distance=0.05)
    other = PointLock(lock.link, lock.link_point, lock.target + [0.01, 0.0, 0.0])
    beyond_limits = np.array([0.0, 0.0, 0.0, 50.0, 0.0, 0.0])
    controller = MinkController(robot, [lock, other], solver=solver,
                                solver_settings=ONE_ITERATION[solver])
    qd = controller.solve(q, beyond_limits)
    assert controller.info.success is False
    assert np.array_equal(qd, np.zeros(robot.model.nv))
    assert "mink" in controller.info.message and solver in controller.info.message
    strict = MinkController(robot, [lock, other], solver=solver, strict=True,
                            solver_settings=ONE_ITERATION[solver])
    with pytest.raises(SolverError, match="mink"):
        strict.solve(q, beyond_limits)


def test_barrier_is_held_against_a_push_like_the_qp(ur5_instrument):
    """The tip pushes down on a barrier 0.2 mm below it: mink stops where the QP does."""
    robot = ur5_instrument
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.2)
    data = kinematics(robot, q)
    tip = data.oMf[robot.model.getFrameId("tool_tip")]
    barrier = Barrier("tool_tip", [0.0, 0.0, 0.0], tip.translation - [0.0, 0.0, 2e-4],
                      [0.0, 0.0, 1.0])
    twist = np.concatenate([tip.rotation.T @ np.array([0.0, 0.0, -0.05]), np.zeros(3)])
    A_b, b_b = barrier.rows(robot.model, data)
    for solver in ("daqp", "proxqp"):
        expected = QPController(robot, [hole, barrier], solver=solver).solve(q, twist)
        controller = MinkController(robot, [hole, barrier], solver=solver)
        qd = controller.solve(q, twist)
        assert controller.info.success, controller.info.message
        np.testing.assert_allclose(qd, expected, atol=AGREEMENT)
        assert controller.info.active_barriers == (1,)
        assert A_b @ qd == pytest.approx(b_b, abs=1e-9)  # on the boundary: -K d
        assert controller.info.equality_residual <= 1e-9
    # pulled away, the barrier is inactive and the twist is tracked
    controller = MinkController(robot, [hole, barrier])
    qd = controller.solve(q, -twist)
    assert controller.info.active_barriers == ()
    np.testing.assert_allclose(ee_jacobian(robot, q) @ qd, -twist, atol=1e-8)


# ----------------------------------------------------------------------------- API


def test_set_constraints_rebuilds_the_tasks(sda10f):
    robot = sda10f
    q = robot.q_home.copy()
    controller = MinkController(robot)
    twist = small_twist(np.random.default_rng(1))
    free = controller.solve(q, twist)
    assert controller.constraint_tasks == [] and controller.info.equality_residual == 0.0
    hole = Hole.on_link(robot, q, distance=0.08)
    controller.set_constraints([hole])
    assert [t.constraint for t in controller.constraint_tasks] == [hole]
    held = controller.solve(q, twist)
    np.testing.assert_allclose(held, CJMController(robot, [hole], **EXACT).solve(q, twist),
                               atol=AGREEMENT)
    assert np.abs(held - free).max() > 1e-6  # the hole changed the answer
    controller.set_constraints([])
    np.testing.assert_allclose(controller.solve(q, twist), free, atol=1e-12)


def test_bad_arguments_raise(sda10f):
    with pytest.raises(ValueError, match="solver"):
        MinkController(sda10f, solver="no-such-solver")
    with pytest.raises(ValueError, match="dt"):
        MinkController(sda10f, dt=0.0)
    with pytest.raises(ValueError, match="unknown link"):
        MinkController(sda10f, [Hole("no_link", [0.0, 0.0, 0.0])])
    controller = MinkController(sda10f)
    with pytest.raises(ValueError, match="twist"):
        controller.solve(sda10f.q_home.copy(), np.full(6, np.nan))


def test_custom_limits(sda10f):
    """``limits=()`` drops the defaults; factories get the MuJoCo model."""
    import mink

    q = sda10f.q_home.copy()
    big = np.array([0.0, 0.0, 0.0, 50.0, 0.0, 0.0])  # 50 rad/s about x: beyond every limit
    free = MinkController(sda10f, limits=())
    assert np.abs(free.solve(q, big)).max() > 3.0
    limited = MinkController(sda10f, limits=[lambda model: mink.VelocityLimit(
        model, {name: 1.0 for name in free.joints.names})])
    qd = limited.solve(q, big)
    assert limited.info.success
    assert np.abs(qd).max() <= 1.0 + 1e-9
