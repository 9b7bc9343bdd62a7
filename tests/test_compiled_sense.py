"""The compiled tick's measure for the supervisor (``CompiledTick.sense``, ``Tick::sense``,
docs/design.md 5.1, 5.2): each constraint's violation from the step's own kinematics and
terms against ``Constraint.violation`` at Pinocchio's placements computed here, and the
kinematics it leaves for the period's step reused only at the same configuration.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given
from hypothesis import strategies as st

from constraints import Hole
from controllers.cjm import compiled_forms
from controllers.cjm.compiled_forms import CompiledForm
from teleop.controller_specs import make_controller
from teleop.experiments.bench_problems import bench_problem_named
from teleop.loop import TeleopLoop

#: one problem per compiled kind: a hole, a plane, a point lock, a barrier (one-sided:
#: its violation is the penetration), two holes on the dual arm
PROBLEMS = ("sda10f", "sda10f/plane", "sda10f/lock", "sda10f/barrier", "sda10f_dual")


def compiled_loop(label: str) -> TeleopLoop:
    problem = bench_problem_named(label)
    controller = make_controller("cjm", problem.robot, list(problem.constraints), dt=1e-3)
    loop = TeleopLoop(problem.robot, controller, q0=problem.base)
    assert loop.compiled is not None and loop.compiled.ready()
    return loop


LOOPS = {label: compiled_loop(label) for label in PROBLEMS}


@pytest.mark.parametrize("label", PROBLEMS)
@given(offset=st.lists(st.floats(-0.05, 0.05), min_size=18, max_size=18))
def test_violations_equal_pinocchio_and_the_constraints(label: str, offset: list[float]) -> None:
    """At configurations up to 0.05 rad off the problem's, the compiled violations equal
    ``Constraint.violation`` at ``pin.framesForwardKinematics``'s placements to rounding
    (1e-15 m on violations of at most ~0.1 m)."""
    loop = LOOPS[label]
    model = loop.model
    q = pin.integrate(model, bench_problem_named(label).base, np.array(offset[:model.nv]))
    sensed = loop.compiled.sense(q)
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    expected = [constraint.violation(data.oMf[frame]) for constraint, frame
                in zip(loop.constraints, loop.controller.constraint_frames)]
    assert sensed is not None and len(sensed) == len(expected)
    assert np.allclose(sensed, expected, rtol=0.0, atol=1e-15), (sensed, expected)
    if label == "sda10f/barrier":
        assert min(sensed) >= 0.0


def test_a_configuration_not_finite_measures_nothing() -> None:
    loop = LOOPS["sda10f"]
    q = loop.q.copy()
    q[0] = np.nan
    assert loop.compiled.sense(q) is None
    assert loop.compiled.sense(q[:-1]) is None


@pytest.mark.parametrize("between", ["sense elsewhere", "step elsewhere"])
def test_the_step_recomputes_what_another_configuration_left(between: str) -> None:
    """A period's run after ``sense`` at another configuration, or after the controller
    stepped elsewhere on the same pipeline, gives bit for bit the command of a run that
    sensed nothing: the kinematics are reused only where they were computed."""
    label = "sda10f"
    reference, checked = compiled_loop(label), compiled_loop(label)
    target = reference.ee_placement().copy()
    target.translation += np.array([0.002, -0.001, 0.001])
    other = pin.integrate(reference.model, reference.q, np.full(reference.model.nv, 0.01))
    for _ in range(3):
        q = reference.q.copy()
        expected = reference.compiled.run([target], q, True)
        if between == "sense elsewhere":
            checked.compiled.sense(other)
        else:
            checked.compiled.sense(q)
            checked.controller.solve(other, np.zeros(6))
        result = checked.compiled.run([target], q, True)
        assert np.array_equal(result[1], expected[1])
        assert np.array_equal(result[2], expected[2])
        reference.q = checked.q = expected[2]


class CutHole(Hole):
    """A hole whose compiled parameters are cut to 3 entries once ``cut`` is set."""

    cut: bool = False


def cut_hole_values(hole: CutHole) -> np.ndarray:
    values = compiled_forms.hole_values(hole)
    return values[:3] if hole.cut else values


def test_a_refused_declaration_stops_as_the_python_path(monkeypatch) -> None:
    """A constraint whose compiled parameters the extension refuses at a step (here 3
    entries where a hole declares 10, taken again as an assignment replaced its revision):
    the compiled loop measures in Python and takes the same controlled stop as the loop's
    Python path, no exception out of ``advance``."""
    monkeypatch.setattr(compiled_forms, "COMPILED_FORMS",
                        {**compiled_forms.COMPILED_FORMS,
                         CutHole: CompiledForm("hole", cut_hole_values)})
    compiled_forms.form_of_type.cache_clear()
    steps = []
    for compiled in (True, False):
        problem = bench_problem_named("sda10f")
        first = problem.constraints[0].to_dict()
        del first["kind"]
        constraints = [CutHole(**first), *problem.constraints[1:]]
        controller = make_controller("cjm", problem.robot, constraints, dt=1e-3)
        loop = TeleopLoop(problem.robot, controller, q0=problem.base, compiled_tick=compiled)
        target = loop.ee_placement().copy()
        loop.advance(target)
        constraints[0].cut = True
        steps.append(loop.advance(target))
    compiled_forms.form_of_type.cache_clear()
    for step in steps:
        assert step.status == "failed"
        assert "needs 10 entries, got 3" in step.message
        assert not np.any(step.qd)
    assert steps[0].supervision.error == steps[1].supervision.error
