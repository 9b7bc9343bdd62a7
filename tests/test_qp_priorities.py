"""The QP with the CJM's priorities (docs/design.md section 10), mink's posture task and
``load_robot(..., locked_joints=...)``.

* Redundant and non-redundant outside robots (example-robot-data): the UR5 with a hole
  on ``forearm_link`` (3 joints before it: the general form) and the Panda, fingers
  locked, with a hole on ``panda_link7`` (7 joints before it: a redundant pre-chain).
  Random configurations near a nominal pose and random twists (hypothesis): the
  lexicographic QP (proxqp, daqp) equals the CJM to 1e-6 rad/s and the null-space
  solution written here to 1e-6 rad/s, and the link does not move across its axis at the
  hole by more than 1e-10 m/s, computed here from Pinocchio's frame velocity.
* Generated chains of 16, 32 and 64 DoF with 1, 2, 4 and 8 holes (as many as fit): every
  backend equals the (undamped) CJM with no limit binding, without a failed step (proxqp
  and daqp to 1e-6 rad/s, OSQP to its tolerance carried through the problem's
  conditioning). On the bench's steps, where the joint limits bind, proxqp and daqp fail
  none and give the same command; OSQP's rare failures are honest zero commands.
* Priorities: with limits binding the lexicographic QP misses the twist by no more than
  the CJM (whose command is feasible) nor the weighted QP; the weighted QP equals its
  own objective's minimiser, solved here from its KKT system.
* mink with its posture task stays within the documented deviation from the CJM.
* ``locked_joints`` removes the Panda's fingers and moves no frame.
"""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from constraints import Hole
from controllers import CJMController, MinkController, QPController, StepStatus
from controllers.qp import SOLVER_SETTINGS
from teleop import load_robot
from teleop.robots.chains import hole_links, load_chain
from teleop.robots.catalog import example_robot_data_share

FINGERS = ["panda_finger_joint1", "panda_finger_joint2"]
PANDA_HOME = [0.2, -0.3, 0.1, -2.0, 0.2, 1.8, 0.7, 0.02, 0.02]
UR5_HOME = [0.3, -1.2, 1.6, -1.8, -1.5, 0.4]
#: agreement with the CJM (rad/s) where no limit binds
AGREEMENT = 1e-6
#: the link's speed across its axis at the hole (m/s)
LATERAL = 1e-10
#: (DoF, holes) of the generated chains: ``hole_links`` fits 8 holes in 22 DoF or more
CHAINS = [(dof, count) for dof in (16, 32, 64) for count in (1, 2, 4, 8) if 2 * count + 6 <= dof]

PROPERTY = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FEW = settings(max_examples=4, deadline=None,
               suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


@functools.cache
def ur5():
    share = example_robot_data_share()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # meshes: not needed here
        return load_robot(share / "example-robot-data/robots/ur_description/urdf/ur5_robot.urdf",
                          ee_frame="tool0", constrained_link="forearm_link", link_axis=(0, 0, 1),
                          package_dirs=[str(share)], q_home=UR5_HOME)


@functools.cache
def panda(locked: bool = True):
    share = example_robot_data_share()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_robot(share / "example-robot-data/robots/panda_description/urdf/panda.urdf",
                          ee_frame="panda_hand", constrained_link="panda_link7",
                          link_axis=(0, 0, 1), package_dirs=[str(share)], q_home=PANDA_HOME,
                          locked_joints=FINGERS if locked else None)


@functools.cache
def chain(dof: int):
    return load_chain(dof)


def kinematics(robot, q):
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    return data


def lateral_speed(robot, q, hole: Hole, qd) -> float:
    """How fast the link moves across its axis at the hole (m/s), from Pinocchio alone:
    the velocity of the link's material point nearest the hole centre, less its part
    along the axis."""
    data = kinematics(robot, q)
    frame = robot.model.getFrameId(hole.link)
    placement = data.oMf[frame]
    axis = placement.rotation @ (np.asarray(hole.link_axis) / np.linalg.norm(hole.link_axis))
    point = placement.translation + axis * float(axis @ (hole.center - placement.translation))
    jacobian = pin.getFrameJacobian(robot.model, data, frame, pin.LOCAL_WORLD_ALIGNED)
    linear, angular = jacobian[:3] @ qd, jacobian[3:] @ qd
    velocity = linear + np.cross(angular, point - placement.translation)
    return float(np.linalg.norm(velocity - axis * float(axis @ velocity)))


def reference_lexicographic(robot, q, holes, twist, posture_velocity) -> np.ndarray:
    """The rows, then the twist in the least-squares sense, then the posture, with no
    inequality: ``qd = qd_0 + N y``, written with NumPy's SVDs."""
    data = kinematics(robot, q)
    rows = [hole.rows(robot.model, data) for hole in holes]
    A, b = np.vstack([r[0] for r in rows]), np.concatenate([r[1] for r in rows])
    J = pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(robot.ee_frame), pin.LOCAL)
    qd_0 = np.linalg.pinv(A) @ b
    _, s, vt = np.linalg.svd(A)
    N = vt[int(np.sum(s > 1e-10 * s[0])):].T
    task = J @ N
    y = np.linalg.pinv(task, rcond=1e-10) @ (twist - J @ qd_0)
    _, s_t, vt_t = np.linalg.svd(task)
    spare = vt_t[int(np.sum(s_t > 1e-10 * s_t[0])):].T  # null(J N), in N's coordinates
    return qd_0 + N @ (y + spare @ (spare.T @ (N.T @ posture_velocity)))


def twists(scale: float):
    return arrays(float, 6, elements=st.floats(-scale, scale, allow_nan=False))


def offsets(size: int, spread: float):
    return arrays(float, size, elements=st.floats(-spread, spread, allow_nan=False))


def assert_inside(controller, q, qd):
    lower, upper = controller.bounds(q)
    slack = 1e-9 * np.where(np.isfinite(controller.velocity_limit), controller.velocity_limit, 1.0)
    assert np.all(np.isfinite(qd))
    assert np.all(qd >= lower - slack) and np.all(qd <= upper + slack)


# ------------------------------------------------------------ outside robots, no limits binding


@pytest.mark.parametrize("name", ["ur5", "panda"])
@PROPERTY
@given(data=st.data())
def test_lexicographic_qp_is_the_cjm_on_the_ur5_and_the_panda(name, data):
    robot = ur5() if name == "ur5" else panda()
    q = robot.q_home + data.draw(offsets(robot.nq, 0.15), label="q offset")
    twist = data.draw(twists(0.05), label="twist")
    hole = Hole.on_link(robot, q, distance=0.2 if name == "ur5" else 0.05)
    cjm = CJMController(robot, [hole])
    qd_cjm = cjm.solve(q, twist)
    assert cjm.info.method == ("general" if name == "ur5" else "analytical")
    assert cjm.info.damping == 0.0  # the CJM is exact here: the comparison is meaningful
    assert_inside(cjm, q, qd_cjm)
    posture = 1.0 * pin.difference(robot.model, q, robot.q_home)  # gain 1 1/s, home
    np.testing.assert_allclose(qd_cjm, reference_lexicographic(robot, q, [hole], twist, posture),
                               atol=AGREEMENT)
    assert lateral_speed(robot, q, hole, qd_cjm) <= LATERAL
    for solver in ("proxqp", "daqp"):
        qp = QPController(robot, [hole], solver=solver)
        qd = qp.solve(q, twist)
        assert qp.info.success, qp.info.message
        assert qp.info.method == f"qp:{solver}"
        assert_inside(qp, q, qd)
        np.testing.assert_allclose(qd, qd_cjm, atol=AGREEMENT)
        assert lateral_speed(robot, q, hole, qd) <= LATERAL


def test_the_panda_redundancy_goes_to_the_posture_not_to_the_minimum_norm():
    """The case of the issue: the QP spent the redundancy on ``mu |qd|^2`` (17 mrad/s off
    the CJM here, up to 0.23 rad/s elsewhere), the CJM on its posture."""
    robot = panda()
    q = robot.q_home + np.array([0.1, -0.1, 0.1, 0.1, -0.1, 0.1, -0.1])
    hole = Hole.on_link(robot, q, distance=0.05)
    twist = np.array([0.01, -0.02, 0.015, 0.03, -0.02, 0.01])
    qd_cjm = CJMController(robot, [hole]).solve(q, twist)
    minimum_norm = CJMController(robot, [hole], posture_gain=0.0).solve(q, twist)
    assert np.abs(qd_cjm - minimum_norm).max() > 1e-2  # the posture matters here
    for solver in ("proxqp", "daqp", "osqp"):
        np.testing.assert_allclose(QPController(robot, [hole], solver=solver).solve(q, twist),
                                   qd_cjm, atol=AGREEMENT)
        np.testing.assert_allclose(
            QPController(robot, [hole], solver=solver, posture_gain=0.0).solve(q, twist),
            minimum_norm, atol=AGREEMENT)


# ------------------------------------------------------------------------ generated chains


def chain_problem(dof: int, count: int, offset: np.ndarray):
    robot = chain(dof)
    q = robot.q_home + offset
    return robot, q, [Hole.on_link(robot, q, 0.05, link=link) for link in hole_links(dof, count)]


def osqp_bound(robot, q, holes) -> float:
    """OSQP's residual tolerance as a bound on ``qd`` (rad/s): a stationarity residual
    ``r`` (each entry at most ``eps_abs``) leaves ``qd`` within ``|r| / lambda_min`` of
    the solution, ``lambda_min`` the smallest non-zero eigenvalue of the QP's normalised
    Hessian ``M^T M``, ``M = [A; J / sqrt(s)]``."""
    data = kinematics(robot, q)
    A = np.vstack([h.rows(robot.model, data)[0] for h in holes])
    J = pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(robot.ee_frame), pin.LOCAL)
    singular = np.linalg.svd(np.vstack([A, J / math.sqrt(np.sum(J * J) / 6.0)]), compute_uv=False)
    smallest = singular[singular > 1e-10 * singular[0]][-1]
    return math.sqrt(robot.nv) * SOLVER_SETTINGS["osqp"]["eps_abs"] / smallest**2


@pytest.mark.parametrize("dof, count", CHAINS)
@FEW
@given(data=st.data())
def test_every_backend_is_the_cjm_on_generated_chains(dof, count, data):
    robot, q, holes = chain_problem(dof, count, data.draw(offsets(dof, 0.1), label="q offset"))
    twist = data.draw(twists(0.01), label="twist")  # no joint near its limit (premise below)
    # the exact CJM: some of these chains sit near its damping threshold (sigma 0.0098 <
    # 0.01 on the 16-DoF chain with 4 holes), where the default CJM damps and the QP does not
    cjm = CJMController(robot, holes, singular_threshold=0.0)
    qd_cjm = cjm.solve(q, twist)
    assert cjm.info.method != "saturated" and cjm.info.damping == 0.0  # exact, unlimited
    for solver, tolerance in (("proxqp", AGREEMENT), ("daqp", AGREEMENT),
                              ("osqp", osqp_bound(robot, q, holes))):
        # numerics, not timing: no deadline (a 64-DoF step may take over 10 ms of CPU)
        qp = QPController(robot, holes, solver=solver, time_budget=None,
                          singular_threshold=0.0)  # undamped, as the CJM here (10.7)
        qd = qp.solve(q, twist)
        assert qp.info.success, qp.info.message
        assert qp.info.equality_residual <= 1e-9
        assert_inside(qp, q, qd)
        np.testing.assert_allclose(qd, qd_cjm, atol=tolerance, err_msg=solver)
    for hole in holes:
        assert lateral_speed(robot, q, hole, qd_cjm) <= LATERAL


#: the bench's twist (``teleop bench``): a few mm/s and mrad/s
BENCH_TWIST = np.array([0.001, -0.002, 0.0015, 0.005, -0.003, 0.002])


@functools.cache
def bench_problem(dof: int, count: int):
    """The bench's problem: holes placed at home; its steps put the arm up to 1 mrad off
    home, so the holes' drift correction asks for more than the velocity limits."""
    robot = chain(dof)
    holes = [Hole.on_link(robot, robot.q_home, 0.05, link=link) for link in hole_links(dof, count)]
    # numerics, not timing: no deadline (a 64-DoF step may take over 10 ms of CPU)
    return robot, holes, {solver: QPController(robot, holes, solver=solver, time_budget=None)
                          for solver in ("proxqp", "daqp", "osqp")}


@pytest.mark.parametrize("dof, count", CHAINS)
@FEW
@given(data=st.data())
def test_no_backend_fails_where_the_limits_bind_on_generated_chains(dof, count, data):
    robot, holes, controllers = bench_problem(dof, count)
    q = robot.q_home + data.draw(offsets(dof, 1e-3), label="q offset")
    cjm = CJMController(robot, holes)
    cjm.solve(q, BENCH_TWIST)
    event(f"CJM {cjm.info.method}")  # mostly "saturated": a limit binds
    held = {"proxqp": 1e-9, "daqp": 1e-9, "osqp": SOLVER_SETTINGS["osqp"]["eps_abs"]}  # m/s
    commands = {}
    for solver, qp in controllers.items():
        commands[solver] = qp.solve(q, BENCH_TWIST)
        assert_inside(qp, q, commands[solver])
        if solver == "osqp" and not qp.info.success:
            # OSQP stops "solved inaccurate" at its 10^5 iterations on a few of these steps
            # (docs/design.md section 10.3): then the zero command, and said so
            event("osqp failed")
            assert qp.info.status is StepStatus.FAILED and not np.any(commands[solver])
            continue
        assert qp.info.success, (solver, qp.info.message)
        assert qp.info.equality_residual <= held[solver]
    np.testing.assert_allclose(commands["proxqp"], commands["daqp"], atol=AGREEMENT)


# ------------------------------------------------------------------------------ priorities


def task_error(robot, q, qd, twist) -> float:
    data = kinematics(robot, q)
    J = pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(robot.ee_frame), pin.LOCAL)
    return float(np.linalg.norm(J @ qd - twist))


@pytest.mark.parametrize("dof, count", [(32, 2), (32, 4)])
@FEW
@given(data=st.data())
def test_with_limits_binding_the_task_comes_before_the_posture(dof, count, data):
    robot, holes, controllers = bench_problem(dof, count)
    q = robot.q_home + data.draw(offsets(dof, 1e-3), label="q offset")
    cjm = CJMController(robot, holes)
    qd_cjm = cjm.solve(q, BENCH_TWIST)
    assume(cjm.info.method == "saturated")  # a limit binds (every bench step of these)
    assert_inside(cjm, q, qd_cjm)
    assert cjm.info.equality_residual <= 1e-9  # the CJM's command is feasible for the QP
    lexicographic = controllers["daqp"].solve(q, BENCH_TWIST)
    weighted = QPController(robot, holes, solver="daqp", priorities="weighted",
                            mu=1e-2).solve(q, BENCH_TWIST)
    error = task_error(robot, q, lexicographic, BENCH_TWIST)
    # both commands are feasible for the QP's task stage, which minimises this error
    assert error <= task_error(robot, q, qd_cjm, BENCH_TWIST) + 1e-9
    assert error <= task_error(robot, q, weighted, BENCH_TWIST) + 1e-9


@PROPERTY
@given(offset=offsets(7, 0.15), twist=twists(0.05),
       mu=st.sampled_from([1e-2, 1e-4, 1e-6]))
def test_the_weighted_qp_minimises_its_own_objective(offset, twist, mu):
    """``min |J qd - V|^2 / s + mu |qd - qd_posture|^2`` under ``A qd = b``: the KKT
    system solved here (no limit binds at these speeds)."""
    robot = panda()
    q = robot.q_home + offset
    hole = Hole.on_link(robot, q, distance=0.05)
    qp = QPController(robot, [hole], solver="daqp", priorities="weighted", mu=mu)
    qd = qp.solve(q, twist)
    data = kinematics(robot, q)
    A, b = hole.rows(robot.model, data)
    J = pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(robot.ee_frame), pin.LOCAL)
    scale = np.sum(J * J) / 6.0
    posture = qp.posture_velocity(q)
    kkt = np.block([[J.T @ J / scale + mu * np.eye(7), A.T], [A, np.zeros((2, 2))]])
    expected = np.linalg.solve(kkt, np.concatenate([J.T @ twist / scale + mu * posture, b]))[:7]
    np.testing.assert_allclose(qd, expected, atol=1e-8)


def test_priorities_and_posture_are_checked():
    robot = panda()
    with pytest.raises(ValueError, match="priorities"):
        QPController(robot, priorities="strict")
    with pytest.raises(ValueError, match="posture_gain"):
        QPController(robot, posture_gain=-1.0)
    with pytest.raises(ValueError, match="posture"):
        QPController(robot, posture=np.zeros(3))
    with pytest.raises(ValueError, match="mu"):
        QPController(robot, priorities="weighted", mu=0.0)


# ------------------------------------------------------------------------------------ mink


@functools.cache
def minks(name: str):
    """mink with its posture task and without, built once (the MuJoCo model is)."""
    robot = panda() if name == "panda" else chain(32)
    # numerics, not timing: no deadline (a 64-DoF step may take over 10 ms of CPU)
    return robot, MinkController(robot, time_budget=None), MinkController(
        robot, posture_cost=0.0, time_budget=None)


@pytest.mark.parametrize("name, tolerance", [("panda", 1e-6), ("chain32", 2e-5)])
@FEW
@given(data=st.data())
def test_mink_posture_task_stays_within_its_documented_deviation(name, tolerance, data):
    """mink's weighted posture (docs/design.md section 10.5): measured 3e-7 rad/s from the
    CJM on the Panda, up to 6e-6 on the 32-DoF chain."""
    robot, mink, without_posture = minks(name)
    q = robot.q_home + data.draw(offsets(robot.nq, 0.1), label="q offset")
    twist = data.draw(twists(0.03), label="twist")
    links = [None] if name == "panda" else hole_links(32, 2)
    holes = [Hole.on_link(robot, q, 0.05, link=link) for link in links]
    cjm = CJMController(robot, holes)
    qd_cjm = cjm.solve(q, twist)
    assert cjm.info.method != "saturated" and cjm.info.damping == 0.0
    mink.set_constraints(holes)
    qd = mink.solve(q, twist)
    assert mink.info.success, mink.info.message
    np.testing.assert_allclose(qd, qd_cjm, atol=tolerance)
    without_posture.set_constraints(holes)
    # without it mink spends the redundancy on the minimum norm, as the CJM would at gain 0
    np.testing.assert_allclose(without_posture.solve(q, twist),
                               CJMController(robot, holes, posture_gain=0.0).solve(q, twist),
                               atol=100 * tolerance)


# ---------------------------------------------------------------------------- locked joints


def test_locked_fingers_leave_seven_joints_and_move_no_frame():
    full, reduced = panda(locked=False), panda()
    assert full.nq == 9 and reduced.nq == reduced.nv == 7
    assert [reduced.model.names[j] for j in range(1, reduced.model.njoints)] == [
        f"panda_joint{i}" for i in range(1, 8)]
    assert dict(reduced.locked_joints) == {"panda_finger_joint1": (0.02,),
                                           "panda_finger_joint2": (0.02,)}
    np.testing.assert_array_equal(reduced.q_home, PANDA_HOME[:7])
    data_full, data_reduced = kinematics(full, full.q_home), kinematics(reduced, reduced.q_home)
    for frame in ("panda_hand", "panda_link7", "panda_leftfinger", "panda_hand_tcp"):
        np.testing.assert_allclose(
            data_reduced.oMf[reduced.model.getFrameId(frame)].homogeneous,
            data_full.oMf[full.model.getFrameId(frame)].homogeneous, atol=1e-12)


def test_locked_configuration_sets_where_the_fingers_are_held():
    share = example_robot_data_share()
    urdf = share / "example-robot-data/robots/panda_description/urdf/panda.urdf"
    held = np.array([0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0, 0.035, 0.01])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = load_robot(urdf, ee_frame="panda_hand", q_home=PANDA_HOME,
                           locked_joints=FINGERS, locked_configuration=held)
        full = load_robot(urdf, ee_frame="panda_hand", q_home=PANDA_HOME)
    assert dict(robot.locked_joints) == {"panda_finger_joint1": (0.035,),
                                         "panda_finger_joint2": (0.01,)}
    q_full = np.concatenate([robot.q_home, held[7:]])
    data, data_full = kinematics(robot, robot.q_home), kinematics(full, q_full)
    for frame in ("panda_leftfinger", "panda_rightfinger"):
        np.testing.assert_allclose(data.oMf[robot.model.getFrameId(frame)].homogeneous,
                                   data_full.oMf[full.model.getFrameId(frame)].homogeneous,
                                   atol=1e-12)
    mink = MinkController(robot, [])  # MuJoCo's model has the fingers fixed where they are held
    mink.solve(robot.q_home, np.zeros(6))
    for frame in ("panda_hand", "panda_leftfinger", "panda_rightfinger"):
        np.testing.assert_allclose(mink.site_pose(frame).homogeneous,
                                   data.oMf[robot.model.getFrameId(frame)].homogeneous, atol=1e-9)


def test_bad_locked_joints_are_refused_by_name():
    share = example_robot_data_share()
    urdf = share / "example-robot-data/robots/panda_description/urdf/panda.urdf"

    def load(**options):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return load_robot(urdf, ee_frame="panda_hand", q_home=PANDA_HOME, **options)

    with pytest.raises(ValueError, match="locked_joints: unknown joint 'gripper'"):
        load(locked_joints=["gripper"])
    with pytest.raises(ValueError, match="locked_joints must be a list"):
        load(locked_joints="panda_finger_joint1")
    with pytest.raises(ValueError, match="twice"):
        load(locked_joints=["panda_finger_joint1", "panda_finger_joint1"])
    with pytest.raises(ValueError, match="nothing left"):
        load(locked_joints=[f"panda_joint{i}" for i in range(1, 8)] + FINGERS)
    with pytest.raises(ValueError, match="locked_configuration"):
        load(locked_configuration=np.zeros(9))
    with pytest.raises(ValueError, match="locked_configuration is outside"):
        load(locked_joints=FINGERS, locked_configuration=[0.0] * 7 + [0.5, 0.0])
    with pytest.raises(ValueError, match="locked_configuration must have size"):
        load(locked_joints=FINGERS, locked_configuration=[0.0] * 7)
