"""The compiled step's own kinematics (Pinocchio's templates in the C++ extension, a copy
of the model, docs/design.md section 16) equal Pinocchio's Python kinematics, and what
the compiled step reads each step (hole anchors, gains, inputs) reaches it.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from constraints import Hole
from controllers import CJMController
from controllers.cjm import _step
from controllers.cjm.compiled import joint_specs
from controllers.cjm.controller import unsupported_joint_kinds
from controllers.cjm.tolerances import StepTolerances
from teleop.robots import load_robot
from teleop.robots.chains import load_chain

ROBOTS = {name: load_robot(name)
          for name in ("sda10f", "ur5_instrument", "sda10f_dual", "sda10f_dual_mobile")}
ROBOTS["chain16"] = load_chain(16)


def holes_on(robot) -> list[Hole]:
    """A hole on each constrained link, where the link is at home."""
    links = robot.constrained_links or [robot.constrained_link]
    return [Hole.on_link(robot, robot.q_home, distance=0.08, link=link) for link in links]


def random_configuration(robot, seed: int) -> np.ndarray:
    """Uniform inside the joint limits; the planar base anywhere within 2 m, any heading."""
    model = robot.model
    rng = np.random.default_rng(seed)
    lower = np.clip(model.lowerPositionLimit, -2.0, 2.0)  # the base's are +-inf or huge
    upper = np.clip(model.upperPositionLimit, -2.0, 2.0)
    q = rng.uniform(lower, upper)
    if robot.root_joint == "planar":  # (x, y, cos, sin) of a random heading
        heading = rng.uniform(-np.pi, np.pi)
        q[2:4] = np.cos(heading), np.sin(heading)
    return q


@settings(max_examples=60, deadline=None)
@given(name=st.sampled_from(sorted(ROBOTS)), seed=st.integers(0, 2**32 - 1))
def test_placements_and_jacobians_equal_pinocchio(name, seed):
    """Every frame the step reads (the EEs, then each constraint's link): placement and
    LOCAL Jacobian equal ``pin.updateFramePlacement`` / ``pin.getFrameJacobian`` to 1e-12."""
    robot = ROBOTS[name]
    controller = CJMController(robot, holes_on(robot), backend="compiled")
    assert_kinematics_equal(controller.step.pipeline, robot.model,
                            [*controller.ee_frame_ids, *controller.constraint_frames],
                            random_configuration(robot, seed), robot.task_size)


def assert_kinematics_equal(pipeline: _step.Pipeline, model: pin.Model, frames: list[int],
                            q: np.ndarray, twist_size: int) -> None:
    """The pipeline's placements and LOCAL Jacobians of ``frames`` (in its order) at ``q``
    equal Pinocchio's to 1e-12."""
    assert pipeline.load(q, np.zeros(twist_size))
    pipeline.prepare()
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    for i, frame in enumerate(frames):
        placement = pin.updateFramePlacement(model, data, frame)
        np.testing.assert_allclose(pipeline.placements[i, :9].reshape(3, 3), placement.rotation,
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(pipeline.placements[i, 9:], placement.translation,
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(pipeline.jacobians[6 * i:6 * i + 6],
                                   pin.getFrameJacobian(model, data, frame, pin.LOCAL),
                                   rtol=0, atol=1e-12)


def fixed_step(model: pin.Model) -> _step.Step:
    """A compiled step with no constraint and no joint limit, for ``model``."""
    return _step.Step(nq=model.nq, nv=model.nv, task_rows=6, damping=0.0, threshold=0.01,
                      max_damping=0.05, general_only=True, constraints=[],
                      box=_step.JointBox(
                          velocity_lower=np.full(model.nv, -1.0), velocity_upper=np.ones(model.nv),
                          velocity_limit=np.ones(model.nv), limited_q=[], limited_v=[],
                          q_min=np.zeros(0), q_max=np.zeros(0), position_gain=0.0,
                          position_limits=False, box_test=np.zeros((0, model.nv + model.nq + 1)),
                          acceleration_step=np.zeros(0), dt=1e-3, limit_gain=1.0,
                          slack=np.zeros(model.nv)),
                      posture_gain=0.0, posture_target=np.zeros(0),
                      tolerances=_step.Tolerances(**dataclasses.asdict(StepTolerances())))


#: one URDF joint of each kind it can give (tilted axes give the unaligned kinds)
EVERY_KIND_URDF = """<robot name="every_kind">
  <link name="base"/>
  {links}
</robot>"""
URDF_JOINTS = [("revolute", "1 0 0"), ("revolute", "0 1 0"), ("revolute", "0 0 1"),
               ("revolute", "0.6 0.8 0"), ("continuous", "1 0 0"), ("continuous", "0 1 0"),
               ("continuous", "0 0 1"), ("continuous", "0 0.28 0.96"), ("prismatic", "1 0 0"),
               ("prismatic", "0 1 0"), ("prismatic", "0 0 1"), ("prismatic", "0.48 0.6 0.64"),
               ("planar", "0 0 1"), ("floating", "0 0 1")]


def every_kind_model() -> pin.Model:
    """A chain with a joint of every kind the compiled kinematics covers, tilted
    placements between them, and a frame on each joint."""
    parts, parent = [], "base"
    for i, (kind, axis) in enumerate(URDF_JOINTS):
        limits = ('<limit lower="-2" upper="2" effort="1" velocity="1"/>'
                  if kind in ("revolute", "prismatic") else "")
        parts.append(f'<link name="l{i}"/><joint name="j{i}" type="{kind}"><parent link="{parent}"/>'
                     f'<child link="l{i}"/><origin xyz="0.1 -0.05 0.2" rpy="0.3 -0.2 0.5"/>'
                     f'<axis xyz="{axis}"/>{limits}</joint>')
        parent = f"l{i}"
    model = pin.buildModelFromXML(EVERY_KIND_URDF.format(links="".join(parts)))
    tilt = pin.SE3(pin.rpy.rpyToMatrix(0.1, 0.4, -0.3), np.array([0.05, 0.1, -0.02]))
    spherical = model.addJoint(model.njoints - 1, pin.JointModelSpherical(), tilt, "ball")
    model.addJoint(spherical, pin.JointModelTranslation(), tilt, "slide3")
    for joint in range(1, model.njoints):
        model.addFrame(pin.Frame(f"on_{joint}", joint, tilt, pin.OP_FRAME))
    return model


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_every_joint_kind_covered_equals_pinocchio(seed):
    """Every kind in ``JOINT_KINDS`` (the unaligned ones' axes read back from Pinocchio):
    the C++ copy's placements and LOCAL Jacobians equal Pinocchio's to 1e-12."""
    model = every_kind_model()
    assert {joint.shortname() for joint in model.joints[1:]} == set(_step.JOINT_KINDS)
    frames = [f for f in range(model.nframes) if model.frames[f].name.startswith("on_")]
    pipeline = _step.Pipeline(
        joints=joint_specs(model),
        frames=[(model.frames[f].parentJoint, model.frames[f].placement.homogeneous) for f in frames],
        step=fixed_step(model), ee_count=len(frames), task_entries=list(range(6)),
        task_scale=np.ones(6))
    rng = np.random.default_rng(seed)
    q = pin.integrate(model, pin.neutral(model), rng.uniform(-2.0, 2.0, model.nv))
    assert_kinematics_equal(pipeline, model, frames, q, 6 * len(frames))


def test_a_joint_kind_not_covered_is_named():
    """A spherical ZYX joint: named by the check, refused by the C++ copy of the model."""
    model = pin.Model()
    base = model.addJoint(0, pin.JointModelSphericalZYX(), pin.SE3.Identity(), "wrist")
    model.addJoint(base, pin.JointModelRZ(), pin.SE3.Identity(), "roll")
    assert unsupported_joint_kinds(model) == ["JointModelSphericalZYX"]
    step = fixed_step(model)
    with pytest.raises(ValueError, match="JointModelSphericalZYX"):
        _step.Pipeline(joints=joint_specs(model), frames=[(2, np.eye(4))], step=step, ee_count=1,
                       task_entries=list(range(6)), task_scale=np.ones(6))


def test_a_robot_with_such_a_joint_runs_the_python_step():
    """``backend="auto"`` falls back to the Python step; ``"compiled"`` says why not."""
    ur5 = ROBOTS["ur5_instrument"]
    model = pin.Model()
    model.addJoint(0, pin.JointModelSphericalZYX(), pin.SE3.Identity(), "wrist")
    model.addFrame(pin.Frame(ur5.ee_frame, 1, pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.1])),
                             pin.OP_FRAME))
    robot = dataclasses.replace(ur5, model=model, q_home=np.zeros(3), constrained_link=None,
                                constrained_links=[], link_axes=[], ee_frames=[ur5.ee_frame])
    controller = CJMController(robot, [])
    assert controller.backend == "python"
    q = np.array([0.3, -0.2, 0.1])
    data = model.createData()
    pin.computeJointJacobians(model, data, q)
    ee_jacobian = pin.getFrameJacobian(model, data, model.getFrameId(ur5.ee_frame), pin.LOCAL)
    twist = ee_jacobian @ np.array([0.1, -0.2, 0.3])  # a twist the wrist can make
    qd = controller.solve(q, twist)
    np.testing.assert_allclose(ee_jacobian @ qd, twist, atol=1e-9)
    with pytest.raises(ValueError, match="JointModelSphericalZYX"):
        CJMController(robot, [], backend="compiled")


def test_moved_holes_and_new_gains_reach_the_compiled_step():
    """Along a path the hole moves (with a velocity fed forward, then at rest) and its gain
    changes: the compiled step follows what the Python step reads from the hole."""
    robot = ROBOTS["sda10f"]
    holes = {backend: Hole.on_link(robot, robot.q_home, distance=0.08) for backend in ("python", "compiled")}
    controllers = {backend: CJMController(robot, [holes[backend]], backend=backend)
                   for backend in holes}
    rng = np.random.default_rng(5)
    twist = np.array([0.01, -0.02, 0.0, 0.05, 0.0, -0.03])
    start = holes["python"].center.copy()
    for step in range(60):
        velocity = np.array([0.02, 0.0, -0.01]) if step < 30 else np.zeros(3)
        center = start + 1e-3 * step * np.array([1.0, 0.0, -0.5])
        for hole in holes.values():
            if step % 3:
                hole.move_to(center, velocity)
            else:  # the attributes assigned directly
                hole.center, hole.velocity = center, velocity
            hole.gain = 50.0 if step % 20 < 10 else 100.0
        q = robot.q_home + rng.uniform(-1e-3, 1e-3, robot.model.nq)
        qd = {backend: controllers[backend].solve(q, twist) for backend in holes}
        np.testing.assert_allclose(qd["compiled"], qd["python"], rtol=0,
                                   atol=1e-12 * max(1.0, np.abs(qd["python"]).max()))
        assert controllers["compiled"].info.status == controllers["python"].info.status


def test_inputs_that_are_not_float_arrays_are_converted():
    """Lists and integer arrays take the checked path and give the same command."""
    robot = ROBOTS["sda10f"]
    controller = CJMController(robot, holes_on(robot), backend="compiled")
    q = robot.q_home.copy()
    twist = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    expected = controller.solve(q, twist)
    np.testing.assert_array_equal(controller.solve(q.tolist(), [0, 0, 0, 1, 0, 0]), expected)
    np.testing.assert_array_equal(controller.solve(q, twist.astype(int)), expected)
    np.testing.assert_array_equal(controller.solve(q[::-1].copy()[::-1], twist), expected)
    with pytest.raises(ValueError, match="q"):
        controller.solve(np.append(q, 0.0), twist)


def test_a_hole_moves_only_through_its_setters():
    """The compiled step copies a hole's anchor when the array changes: in-place edits of
    the centre or velocity are refused, assignments give a new anchor."""
    hole = Hole("link", [0.1, 0.2, 0.3])
    anchor = hole.anchor
    with pytest.raises(ValueError, match="read-only"):
        hole.center[0] += 1.0
    with pytest.raises(ValueError, match="read-only"):
        hole.velocity[:] = 1.0
    hole.center = [0.1, 0.2, 0.4]
    assert hole.anchor is not anchor
    np.testing.assert_array_equal(hole.anchor, [0.1, 0.2, 0.4, 0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="hole velocity"):
        hole.velocity = [0.0, float("nan"), 0.0]


def test_a_copy_of_the_model_that_is_off_is_caught(monkeypatch):
    """A joint placement copied 1 mm off (as a change in pin's Python API could do): the
    one check at build time catches it; ``auto`` runs the Python step, ``compiled`` says
    which frame is off."""
    from controllers.cjm import compiled

    copy_the_model = compiled.joint_specs

    def one_millimetre_off(model):
        specs = copy_the_model(model)
        kind, parent, placement, axis = specs[2]
        placement = placement.copy()
        placement[0, 3] += 1e-3
        specs[2] = (kind, parent, placement, axis)
        return specs

    monkeypatch.setattr(compiled, "joint_specs", one_millimetre_off)
    robot = ROBOTS["sda10f"]
    assert CJMController(robot, holes_on(robot)).backend == "python"
    with pytest.raises(compiled.KinematicsMismatch, match="differ from Pinocchio's by 0.001"):
        CJMController(robot, holes_on(robot), backend="compiled")
