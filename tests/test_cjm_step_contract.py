"""The CJM's step contract (docs/design.md section 16): a frozen StepSetup built from the
controller's public data and built again by its setters, one ``solve(q, twist) -> (qd,
report)`` for both backends, one wording function, tolerances handed to the C++ step.
"""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from constraints import Hole, Plane
from controllers import CJMController, StepStatus
from controllers.cjm import tolerances
from controllers.cjm.compiled import CompiledStep
from controllers.cjm.python_step import PythonStep
from controllers.cjm.report import Event, StepReport, solve_info
from controllers.cjm.tolerances import StepTolerances
from test_compiled_step import assert_same_step

CJM = Path(__file__).resolve().parent.parent / "controllers" / "cjm"


def test_the_setup_is_frozen_and_built_again_by_each_setter(sda10f):
    """Each setter gives a new setup holding the new value; both backends then agree."""
    hole = Hole.on_link(sda10f, sda10f.q_home, distance=0.08)
    python = CJMController(sda10f, [hole], backend="python")
    compiled = CJMController(sda10f, [hole], backend="compiled")
    setup = compiled.setup
    with pytest.raises(dataclasses.FrozenInstanceError):
        setup.posture_gain = 2.0
    with pytest.raises(ValueError):
        setup.posture[0] = 1.0  # its arrays are read-only too
    posture = sda10f.q_home + 0.1
    changes = {"posture_gain": 3.0, "posture": posture, "twist_weight": [1, 1, 1, 0.5, 0.5, 0.5]}
    q = sda10f.q_home + 0.01
    twist = np.array([0.01, -0.02, 0.0, 0.05, 0.0, -0.03])
    for name, value in changes.items():
        for controller in (python, compiled):
            setattr(controller, name, value)
        assert compiled.setup is not setup
        setup = compiled.setup
        assert_same_step(python, compiled, q, twist)
    assert setup.posture_gain == 3.0
    np.testing.assert_array_equal(setup.posture, posture)
    np.testing.assert_allclose(setup.task_scale, np.sqrt([1, 1, 1, 0.5, 0.5, 0.5]))
    with pytest.raises(ValueError, match="posture_gain"):
        compiled.posture_gain = -1.0


def test_both_backends_take_a_setup_and_report_the_same_step(sda10f):
    """``solve(q, twist) -> (qd, report)`` on the controller's setup, worded by solve_info
    into the controller's info: the same command and report from each backend."""
    plane = Plane.through_link_point(sda10f, sda10f.q_home, [0.0, 0.0, 1.0], distance=0.05,
                                     link="arm_link_5_r")
    controller = CJMController(sda10f, [plane], backend="compiled")
    q = sda10f.q_home
    twist = np.array([0.0, 0.0, 0.0, 3.0, 0.0, 0.0])  # a velocity limit binds: scaled
    qd = controller.solve(q, twist)
    steps = (PythonStep(controller.setup, controller.model.createData()),
             CompiledStep(controller.setup))
    for step in steps:
        qd_step, report = step.solve(q, twist)
        assert isinstance(report, StepReport)
        np.testing.assert_allclose(qd_step, qd, rtol=0, atol=1e-9 * (1 + np.abs(qd).max()))
        assert report.status is StepStatus.SCALED
        assert [event for event, *_ in report.events] == [Event.TASK_SCALED]
        info, expected = solve_info(report, controller.joint_names), controller.info
        assert (info.status, info.method, info.message, info.saturated_joints) == \
            (expected.status, expected.method, expected.message, expected.saturated_joints)
    assert solve_info(report, controller.joint_names) == controller.info  # the compiled one
    assert "task scaled to" in controller.info.message


def test_the_compiled_step_decides_with_the_tolerances_it_is_given(sda10f):
    """No copy of the tolerances in the C++ sources: a pivot ratio of 1 makes every
    square pre-chain 'singular' there, and the step hands over to the general form."""
    hole = Hole.on_link(sda10f, sda10f.q_home, distance=0.08)
    controller = CJMController(sda10f, [hole], backend="compiled")
    twist = np.full(6, 0.01)
    _, report = controller.step.solve(sda10f.q_home, twist)
    assert report.method == "analytical"
    strict = dataclasses.replace(controller.setup,
                                 tolerances=StepTolerances(pre_chain_pivot_ratio=1.0))
    _, report = CompiledStep(strict).solve(sda10f.q_home, twist)
    assert report.method == "general"
    assert report.events[0][0] is Event.PRE_CHAIN_SINGULAR


def test_the_tolerances_are_the_modules_constants():
    """StepTolerances holds the numbers of controllers/cjm/tolerances.py, and the C++
    sources define none of them."""
    for field in dataclasses.fields(StepTolerances):
        constant = {"equality": "EQUALITY_TOLERANCE", "twist": "TWIST_TOLERANCE",
                    "barrier": "BARRIER_TOLERANCE", "rank": "RANK_TOLERANCE",
                    "rows": "ROWS_TOLERANCE"}.get(field.name, field.name.upper())
        assert field.default == getattr(tolerances, constant), field.name
    for source in (CJM / "_step").iterdir():
        text = source.read_text()
        assert "Tolerance = 1e" not in text and "kAtBound" not in text, source.name


def test_the_compiled_step_does_not_reach_into_the_controller():
    """compiled.py imports neither controller.py nor a private name of another module
    (no import circle), and reads nothing of a controller."""
    tree = ast.parse((CJM / "compiled.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            assert node.module not in ("controller", "controllers.cjm.controller")
            assert not any(alias.name.startswith("_") and alias.name != "_step"
                           for alias in node.names), ast.dump(node)
        if isinstance(node, ast.Name):
            assert node.id != "controller"


@pytest.mark.parametrize("backend", ["python", "compiled"])
def test_a_refused_change_leaves_the_controller_as_it_was(sda10f, backend):
    """A change the controller cannot take (a plane under the paper's parametrisation, a
    negative posture gain) raises and keeps the constraints, options and step it had:
    what it says it holds is what its step holds (A qd = b of the hole it kept)."""
    q = sda10f.q_home + 0.02
    hole = Hole.on_link(sda10f, q, distance=0.08)
    plane = Plane.through_link_point(sda10f, q, [0.0, 0.0, 1.0], distance=0.05,
                                     link="arm_link_5_r")
    controller = CJMController(sda10f, [hole], parametrisation="paper", backend=backend)
    setup, step, gain = controller.setup, controller.step, controller.posture_gain
    with pytest.raises(ValueError, match="paper"):
        controller.set_constraints([plane])
    with pytest.raises(ValueError, match="posture_gain"):
        controller.posture_gain = -1.0
    assert controller.constraints == [hole]
    assert (controller.setup, controller.step, controller.posture_gain) == (setup, step, gain)
    twist = np.array([0.01, -0.02, 0.0, 0.05, 0.0, -0.03])
    qd = controller.solve(q, twist)
    model = controller.model
    data = model.createData()  # Pinocchio at q (the compiled step keeps its own kinematics)
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    A, b = hole.rows(model, data, controller.constraint_frames[0])
    assert np.abs(A @ qd - b).max() < 1e-9
    assert controller.info.status is StepStatus.OK, controller.info.message


def test_posture_and_twist_weight_are_read_only(sda10f):
    """Changed by assigning a new array (which builds the step again), never in place:
    a change in place would not reach the built step."""
    controller = CJMController(sda10f, [], twist_weight=[1, 1, 1, 0.5, 0.5, 0.5])
    with pytest.raises(ValueError):
        controller.posture[0] = 1.0
    with pytest.raises(ValueError):
        controller.twist_weight[3] = 1.0


def test_the_python_step_refuses_tolerances_it_does_not_decide_with(sda10f):
    """The Python reference decides with the module's constants: a setup carrying other
    tolerances is refused rather than run with different decisions from the compiled step."""
    controller = CJMController(sda10f, [Hole.on_link(sda10f, sda10f.q_home, distance=0.08)])
    custom = dataclasses.replace(controller.setup,
                                 tolerances=StepTolerances(pre_chain_pivot_ratio=1.0))
    with pytest.raises(ValueError, match="tolerances"):
        PythonStep(custom, controller.model.createData())
