"""Regressions found by tests/test_joint_limits.py: the QP backends' false
infeasibilities at the joint limits (the lexicographic QP, docs/design.md section 10,
solves them) and what a step held by a limit or near a singularity says, with both CJM
backends.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
import scipy.optimize
from conftest import HOLE_DISTANCE, kinematics
from test_joint_limits import (ROWS_HELD, UNLIMITED, ee_jacobian, limit_violations, residuals,
                               robot_named, rows_of, twist_error)

from constraints import Barrier, Hole, Plane, PointLock
from controllers import CJMController, QPController, StepStatus
from teleop import load_robot

# ------------------------------------------------- QP false infeasibilities (regressions)
#
# Each was a feasible problem a backend once declared infeasible (a zero command).


def require(condition: bool, message: str) -> None:
    """A premise of a regression case: if it breaks, the test fails with that message."""
    if not condition:
        pytest.fail(f"premise broken: {message}")


def hole_square_case(q):
    """sda10f, a hole exactly on the link (b = 0): ``qd`` is linear in the twist (Jbar 6 x 6)."""
    robot = robot_named("sda10f")
    return robot, [Hole.on_link(robot, q, distance=HOLE_DISTANCE["sda10f"])]


def test_velocity_just_past_the_limit_is_saturated():
    robot = robot_named("sda10f")
    q = robot.q_home.copy()
    _, constraints = hole_square_case(q)
    controller = CJMController(robot, constraints)
    twist = np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02])
    ratio = np.abs(controller.solve(q, twist)) / controller.velocity_limit
    require(controller.info.status is StepStatus.OK and ratio.max() < 1.0, "a free step")
    qd = controller.solve(q, twist * (1.0 + 1.2e-9) / ratio.max())  # 1.2e-9 past a limit
    assert not limit_violations(controller, q, qd), controller.info.status


@pytest.mark.parametrize("gap", [0.0, 1e-8])
def test_command_at_a_position_limit_is_saturated(gap):
    robot = robot_named("sda10f")
    model = robot.model
    q = robot.q_home.copy()
    joint = 1  # arm_joint_1_s, q_max = 3.13
    q[joint] = model.upperPositionLimit[joint] - gap  # at the limit, or 10 nrad below it
    _, constraints = hole_square_case(q)
    twist = np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02])
    free = CJMController(robot, constraints, **UNLIMITED).solve(q, twist)
    controller = CJMController(robot, constraints)
    _, upper = controller.bounds(q)
    # a twist whose unlimited command passes the bound by 1.5e-6 rad/s
    qd = controller.solve(q, twist * np.sign(free[joint]) * (upper[joint] + 1.5e-6) / abs(free[joint]))
    assert not limit_violations(controller, q, qd), (limit_violations(controller, q, qd),
                                                    controller.info.status)


def test_qp_solves_at_a_corner_of_the_joint_box():
    robot = robot_named("sda10f")
    q = robot.model.lowerPositionLimit.copy()  # inside the limits, on every lower one
    _, constraints = hole_square_case(q)  # rows A qd = 0: qd = 0 is feasible
    qp = QPController(robot, constraints, solver="daqp")
    qd = qp.solve(q, np.full(6, -1.0 / np.sqrt(6.0)))
    require(not limit_violations(qp, q, qd), "the fallback is inside the limits")
    assert qp.info.success, qp.info.message


@pytest.mark.parametrize("solver", ["daqp", "proxqp"])
def test_qp_feasibility_does_not_depend_on_the_twist(solver):
    robot = robot_named("sda10f")
    q = np.array([-2.8139544697385315, -1.9797931195599212, -1.272818210366638,
                  -0.15134665159368765, -2.359999999996501, -3.129999960776056,
                  -1.2808946903287008, -3.1154818099795034])  # joints 4 and 5 near q_min
    lock = PointLock("arm_link_5_r", [0.0, 0.0, -0.08], [0.06740445, -0.48342038, 0.2171428])
    direction = np.array([27.427406289837155, -4.285008721503997, -73.69458117640679,
                          10.976476178513893, -43.42117332879655, -37.72552984949108])
    direction /= np.linalg.norm(direction)
    cjm = CJMController(robot, [lock])
    qd_cjm = cjm.solve(q, 100.0 * direction)
    require(not limit_violations(cjm, q, qd_cjm), "the CJM's command is inside the limits")
    require(residuals(robot, q, [lock], qd_cjm)[0] <= ROWS_HELD, "the CJM's command holds the lock")
    slow = QPController(robot, [lock], solver=solver)
    slow.solve(q, 1.0 * direction)
    require(slow.info.success, "the same feasible set with a smaller twist is solved")
    qp = QPController(robot, [lock], solver=solver)
    qp.solve(q, 100.0 * direction)
    assert qp.info.success, qp.info.message


def test_daqp_solves_a_feasible_hole_and_barrier_step():
    robot = robot_named("ur5_instrument")
    q = np.array([0.23511409910469272, -1.5862009815180764, 4.773375721800587, 5.802998937847679,
                  -5.840656718515669, -1.5405593480060586, -1.246090692818183, -0.020560698926300747])
    barrier = Barrier("instrument_shaft", [0.0, 0.0, 0.2], [0.61497384, -0.22380622, 0.57126556],
                      [0.78430213, 0.53877186, 0.3075631])
    hole = Hole("instrument_shaft", [0.6211732, -0.23133769, 0.56778501])
    twist = np.array([-1.0381502105859297e-07, 9.806733296958593e-07, 7.022705027921393e-07,
                      8.963486913564045e-07, -7.714654987742517e-07, -8.097687057339964e-07])
    cjm = CJMController(robot, [barrier, hole])
    qd_cjm = cjm.solve(q, twist)
    require(not limit_violations(cjm, q, qd_cjm), "the CJM's command is inside the limits")
    require(max(residuals(robot, q, [barrier, hole], qd_cjm)) <= ROWS_HELD,
            "the CJM's command holds the hole and the barrier")
    for solver in ("proxqp", "osqp"):  # no deadline: the premise is the QP, not the clock
        other = QPController(robot, [barrier, hole], solver=solver, time_budget=None)
        other.solve(q, twist)
        require(other.info.success, f"{solver} solves the same QP")
    qp = QPController(robot, [barrier, hole], solver="daqp")
    qp.solve(q, twist)
    assert qp.info.success, qp.info.message


def plane_at_the_box_corner():
    """ur5_instrument with every joint at a position limit (Hypothesis 6.170.17's draw of
    test_with_limits_active_cjm_and_qp_stay_inside_and_the_qp_tracks_no_worse): a plane on
    the shaft whose row, at this singular configuration, is ``[-0.817, 1.1e-8, 1.1e-8,
    1.1e-8, -3.4e-8, ~0, 0, 0]``, nearly the bound of joint 0 (at its upper limit)."""
    robot = robot_named("ur5_instrument")
    model = robot.model
    q = model.lowerPositionLimit.copy()
    q[0] = model.upperPositionLimit[0]
    plane = Plane("instrument_shaft", [0.0, 0.0, 0.2], [-0.81725, -0.39145, -0.005491],
                  [1.19e-7, 1.0, 0.0], gain=100.0)
    return robot, q, [plane], np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def least_squares_reference(robot, q, constraints, twist, lower, upper) -> np.ndarray:
    """``argmin |J qd - V|`` under the plane's row and the box, by SciPy's SLSQP: the row
    solved for its largest entry's joint ``k``, whose bounds become one normalised row on
    the other joints."""
    (A, b), _, data = rows_of(robot, q, constraints)
    J = ee_jacobian(robot, data)
    nv = robot.model.nv
    k = int(np.argmax(np.abs(A[0])))
    rest = [i for i in range(nv) if i != k]
    lift = np.zeros((nv, nv - 1))  # qd = lift y + offset
    lift[rest, range(nv - 1)] = 1.0
    lift[k] = -A[0, rest] / A[0, k]
    offset = np.zeros(nv)
    offset[k] = b[0] / A[0, k]
    size = np.linalg.norm(lift[k])
    row = lift[k] / size
    bounds_k = [{"type": "ineq", "fun": lambda y: (upper[k] - offset[k]) / size - row @ y,
                 "jac": lambda y: -row},
                {"type": "ineq", "fun": lambda y: row @ y - (lower[k] - offset[k]) / size,
                 "jac": lambda y: row}]
    result = scipy.optimize.minimize(
        lambda y: 0.5 * float(np.sum((J @ (lift @ y + offset) - twist) ** 2)), np.zeros(nv - 1),
        jac=lambda y: (J @ lift).T @ (J @ (lift @ y + offset) - twist), method="SLSQP",
        bounds=list(zip(lower[rest], upper[rest])), constraints=bounds_k,
        options={"ftol": 1e-15, "maxiter": 1000})
    assert result.success, result.message
    return lift @ result.x + offset


@pytest.mark.parametrize("solver", ["daqp", "proxqp", "osqp"])
def test_qp_tracks_as_the_cjm_where_a_row_nearly_is_a_joint_bound(solver):
    """The task stage where the plane's row and joint 0's bound are 4e-8 rad apart: daqp
    declared it infeasible (the least-residual command, twist error 1.0), proxqp failed,
    OSQP broke the row (``constraint_degraded``). Over ``null(A)`` (docs/design.md 10.2)
    every backend tracks as the CJM and SciPy's reference, rows held."""
    robot, q, constraints, twist = plane_at_the_box_corner()
    cjm = CJMController(robot, constraints)
    qd_cjm = cjm.solve(q, twist)
    require(cjm.info.method == "saturated", "a limit binds the CJM")
    reference = least_squares_reference(robot, q, constraints, twist, *cjm.bounds(q))
    require(not limit_violations(cjm, q, reference), "the reference is inside the box")
    require(max(residuals(robot, q, constraints, reference)) <= ROWS_HELD,
            "the reference holds the plane")
    error_reference = twist_error(robot, q, reference, twist)
    error_cjm = twist_error(robot, q, qd_cjm, twist)
    assert error_cjm == pytest.approx(0.99980010073829, abs=1e-9)
    assert error_reference == pytest.approx(error_cjm, abs=1e-9)
    qp = QPController(robot, constraints, solver=solver, singular_threshold=0.0,
                      time_budget=None)  # the premise is the QP, not the clock
    qd = qp.solve(q, twist)
    assert not limit_violations(qp, q, qd), qp.info.status
    assert max(residuals(robot, q, constraints, qd)) <= ROWS_HELD
    assert qp.info.status is StepStatus.LEAST_SQUARES, qp.info.message  # rows held, twist not
    assert twist_error(robot, q, qd, twist) <= error_reference + 1e-9


# ------------------------------------------------------------------ what the message says


def least_squares_scene_step():
    """A state recorded in the UI (tests/data/least_squares_scene.json, recorded in the
    UI): the hole on ``arm_link_5_r``, every joint well inside its limits, a twist the
    arm cannot give near a singularity of ``J_e N``."""
    import json
    from pathlib import Path

    from constraints import Constraint

    scene = json.loads((Path(__file__).parent / "data" / "least_squares_scene.json").read_text())
    robot = load_robot("sda10f", q_home=scene["robot"]["q_home"])
    hole = Constraint.from_dict(scene["constraints"][0]["constraint"])
    q = np.array([-0.764, -0.812, -0.040, 1.486, -1.700, 0.083, -1.000, 0.598])
    twist = np.array([0.0426, -0.0249, 0.0815, -0.0073, -0.011, 0.0])
    return robot, hole, q, twist


@pytest.mark.parametrize("backend", ["python", "compiled"])
def test_a_damped_step_says_it_is_near_a_singularity_not_at_a_joint_limit(backend):
    """The message named a joint limit ("joint - at a limit") with no joint saturated.
    It must name what limits the step: the damping near a singularity of ``J_e N``, with
    the sigma_min and lambda computed here from the SVD of ``J_e N`` and eq 35."""
    robot, hole, q, twist = least_squares_scene_step()
    controller = CJMController(robot, [hole], backend=backend)
    qd = controller.solve(q, twist)
    info = controller.info
    lower, upper = controller.bounds(q)
    assert np.all(lower < -1.0) and np.all(upper > 1.0)  # every joint far from its limits
    data = kinematics(robot, q)
    rows, _ = hole.rows(robot.model, data)
    jacobian = pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(robot.ee_frame),
                                    pin.LOCAL)
    sigma_min = np.linalg.svd(jacobian @ scipy.linalg.null_space(rows), compute_uv=False)[-1]
    damping = np.sqrt(controller.policy.lambda_squared(sigma_min))
    assert sigma_min < controller.policy.threshold  # the premise: damping acts
    assert info.status is StepStatus.LEAST_SQUARES and info.saturated_joints == ()
    assert info.sigma_min == pytest.approx(sigma_min, rel=1e-9)
    assert info.damping == pytest.approx(damping, rel=1e-9)
    assert info.message == (f"near a singularity (sigma_min {sigma_min:.2g}, damping "
                            f"{damping:.2g}): task not fully achievable"), info.message
    assert np.all(np.isfinite(qd)) and np.all(qd >= lower) and np.all(qd <= upper)


@pytest.mark.parametrize("backend", ["python", "compiled"])
def test_a_step_held_by_a_joint_limit_names_the_joint(backend):
    """A joint at its position limit that the task pushes on: the message names it."""
    robot = robot_named("sda10f")
    q = robot.q_home.copy()
    joint = 1  # arm_joint_1_s
    q[joint] = robot.model.upperPositionLimit[joint]
    _, constraints = hole_square_case(q)
    twist = np.array([0.01, -0.02, 0.015, 0.05, -0.03, 0.02])
    free = CJMController(robot, constraints, **UNLIMITED).solve(q, twist)
    controller = CJMController(robot, constraints, backend=backend)
    controller.solve(q, twist * np.sign(free[joint]))  # towards the limit
    info = controller.info
    assert joint in info.saturated_joints
    names = [robot.model.names[robot.model.joints[j].id] for j in range(1, robot.model.njoints)]
    saturated = [names[i] for i in info.saturated_joints]
    assert "arm_joint_1_s" in saturated
    assert info.message.startswith(f"joint{'s' if len(saturated) > 1 else ''} "
                                   f"{', '.join(saturated)} at a limit"), info.message
