"""A CJM step's report is built when read (docs/design.md section 16): ``CJMController.solve``
leaves it to the first read of ``report`` or ``info``, and the compiled step leaves the
report's ``sigma_min`` of an undamped QR solve to that read too. What is read must be what
the step would have reported at once: compared, field by field, with the report of a twin
controller's step built eagerly (``step.solve``), and its ``sigma_min`` with the Python
backend's (an independent implementation: an SVD through numpy's LAPACK).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from controllers.cjm import CJMController
from controllers.cjm.report import StepReport
from teleop.experiments.bench_problems import (Problem, bench_configurations, bench_problem_named,
                                               bench_twist)

#: a hole (analytical form, LU fast path and DLS), the lock (least squares every step) and
#: the dual robot (the general form's QR solve of a 12 x 11 task, least squares mostly)
PROBLEMS = ("sda10f", "sda10f/lock", "sda10f_dual")


@pytest.fixture(scope="module", params=PROBLEMS)
def problem(request: pytest.FixtureRequest) -> Problem:
    return bench_problem_named(request.param)


def controller_of(problem: Problem, backend: str) -> CJMController:
    return CJMController(problem.robot, list(problem.constraints), backend=backend,
                         acceleration_limit=None)


def same_report(read: StepReport, eager: StepReport) -> None:
    """Every field equal (NaN equal to NaN: a step with no DLS has no sigma_min)."""
    for field in dataclasses.fields(StepReport):
        a, b = getattr(read, field.name), getattr(eager, field.name)
        if isinstance(a, float) and math.isnan(a):
            assert isinstance(b, float) and math.isnan(b), field.name
        else:
            assert a == b, (field.name, a, b)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), unread=st.integers(0, 3))
def test_the_report_read_late_is_the_step_s_own(problem: Problem, seed: int, unread: int):
    """``unread`` steps whose report nobody reads, then one read after the C++ floor's loop
    ran on other configurations: the report read is the last step's, as the twin's step
    built it at once, and its sigma_min is the Python backend's."""
    configurations = bench_configurations(problem.robot, problem.constraints, unread + 1 + 8,
                                          seed=seed)
    twist = bench_twist(problem.robot, problem.constraints)
    lazy, eager, python = (controller_of(problem, backend)
                           for backend in ("compiled", "compiled", "python"))
    for q in configurations[:unread + 1]:
        lazy.solve(q, twist)
        qd, eager_report = eager.step.solve(q, twist)
        python.solve(q, twist)
    others = configurations[unread + 1:]
    assert lazy.step.time_steps(others, np.tile(twist, (len(others), 1))) is not None
    same_report(lazy.report, eager_report)
    assert lazy.info.status is python.info.status
    sigma_min = lazy.report.sigma_min
    if math.isnan(sigma_min):
        assert math.isnan(python.report.sigma_min)
    else:
        assert sigma_min == pytest.approx(python.report.sigma_min, rel=1e-9, abs=1e-12)


def test_the_dual_robot_s_undamped_steps_leave_sigma_min_to_the_read():
    """The deferred sigma_min is exercised: on the dual robot the general form's task solve
    is an undamped QR solve in most steps, and each report read gives a finite sigma_min,
    the Python backend's SVD's."""
    problem = bench_problem_named("sda10f_dual")
    configurations = bench_configurations(problem.robot, problem.constraints, 40, seed=3)
    twist = bench_twist(problem.robot, problem.constraints)
    lazy, python = controller_of(problem, "compiled"), controller_of(problem, "python")
    undamped = 0
    for q in configurations:
        lazy.solve(q, twist)
        python.solve(q, twist)
        report = lazy.report
        undamped += report.damping == 0.0
        assert math.isfinite(report.sigma_min)
        assert report.sigma_min == pytest.approx(python.report.sigma_min, rel=1e-9)
    assert undamped >= 30


def test_the_walk_s_undamped_steps_leave_sigma_min_to_the_read():
    """With acceleration limits the saturation around the previous command decides its
    damping rows on ``J N`` (docs/design.md 9.1): undamped by the QR, their sigma_min is
    left to the report's read too. On ``fast-lateral``'s periods, where the box binds most
    steps, each report read late is the eager twin's field by field and its sigma_min the
    Python backend's SVD's."""
    from teleop.controller_specs import ROBOT, make_controller
    from teleop.experiments.bench_loop import ACCELERATION_SCENARIO, scenario_periods
    from teleop.experiments.scenarios import load_scenario

    plan = load_scenario(ACCELERATION_SCENARIO)
    configurations, twists = scenario_periods(ACCELERATION_SCENARIO, 0.4, acceleration_limits=True)
    lazy, eager, python = (make_controller(spec, plan.robot, plan.make_constraints(), dt=1e-3,
                                           acceleration_limit=ROBOT)
                           for spec in ("cjm", "cjm", "cjm:python"))
    assert isinstance(lazy, CJMController) and isinstance(eager, CJMController)
    assert lazy.backend == "compiled"
    undamped_walks = 0
    for q, twist in zip(configurations, twists):
        lazy.solve(q, twist)
        _, eager_report = eager.step.solve(q, twist)
        python.solve(q, twist)
        report = lazy.report
        same_report(report, eager_report)
        assert report.status is python.report.status
        undamped_walks += report.method == "saturated" and report.damping == 0.0
        assert report.sigma_min == pytest.approx(python.report.sigma_min, rel=1e-9, abs=1e-12)
    assert undamped_walks >= len(configurations) // 3  # 196 of the first 400
