"""Item 3 of issue 38: every failed step counted in the report's solver section (a real
QP solver given too few iterations), and "best" marked only beyond a measure's
resolution."""

from __future__ import annotations

import numpy as np
import pytest

from controllers.numerics import PROXQP_RHO, TASK_ACCURACY
from controllers.optimization import proxqp as proxqp_backend
from controllers.optimization.budget import ITERATION_CAPS
from teleop.experiments.compare import compare, metrics_document
from teleop.experiments.metrics_table import TABLE_COLUMNS
from teleop.experiments.report import best_rows, render_report
from teleop.experiments.scenarios import load_scenario
from teleop.loop import LoopConfig


def test_a_solver_out_of_iterations_is_named_and_counted_in_the_report(monkeypatch):
    """proxqp capped at 1 x 1 iterations (the real solver): on joint-limits, where the
    box is active, some steps fail; the report names the message with the number of
    failed steps the run recorded, and the first one."""
    monkeypatch.setitem(ITERATION_CAPS, "proxqp", {"max_iter": 1, "max_iter_in": 1})
    # a capped solve is solved again with PROXQP_CAPPED_RHO, which finishes these stages in
    # one iteration; with the first rho again it runs out a second time
    monkeypatch.setattr(proxqp_backend, "PROXQP_CAPPED_RHO", PROXQP_RHO)
    # and the last solve on a fresh object keeps that one iteration (not ten times it)
    monkeypatch.setattr(proxqp_backend, "PROXQP_FALLBACK_ITERATIONS", 1)
    # and the flat stage's solve after it, whose tolerance-sized rho finishes them in one
    # iteration too, has the first rho again (rho = PROXQP_FLAT_RHO times the tolerance,
    # TASK_ACCURACY times the curvature)
    monkeypatch.setattr(proxqp_backend, "PROXQP_FLAT_RHO", PROXQP_RHO / TASK_ACCURACY)
    plan = load_scenario("joint-limits")
    results = compare(plan, ["qp:proxqp"], duration=0.5, progress=False)
    result = results["qp:proxqp"]
    failed = int(result.columns["failed"].sum())  # the loop's own record of each step
    assert failed > 0
    summary = result.failure_summary
    assert sum(entry["count"] for entry in summary) == failed
    first = int(result.columns["failed"].argmax())
    assert min(entry["first_step"] for entry in summary) == first
    assert "proxqp stopped at its iteration limit (1 x 1 iterations)" in summary[0]["message"]
    document = metrics_document(plan, results, LoopConfig(), 0.5)
    assert document["controllers"]["qp:proxqp"]["failures"] == summary
    page = render_report(document, [])
    solvers = page[page.index("What the solvers said"):]
    assert "Nothing" not in solvers
    assert f"<td>qp:proxqp</td><td>{summary[0]['count']}</td><td>{first}," in solvers
    assert "proxqp stopped at its iteration limit (1 x 1 iterations)" in solvers


def test_no_failure_and_no_output_says_nothing():
    plan = load_scenario("paper-hole")
    results = compare(plan, ["cjm"], duration=0.05, progress=False)
    assert results["cjm"].failure_summary == []
    page = render_report(metrics_document(plan, results, LoopConfig(), 0.05), [])
    assert "Nothing: no step failed, and no solver printed or warned" in page


def metrics(**values: float) -> dict:
    row: dict = {key: 0.0 for _, key, _ in TABLE_COLUMNS}
    row.update(failed_steps=0, step_time_median_us=5.0, step_time_p99_us=9.0,
               joint_velocity_deviation_max_radps=None)
    row.update(values)
    return row


@pytest.mark.parametrize("errors, best", [
    # 1e-16 apart: a tie, both best; the third 4 nm above them
    ((1.0e-9, 1.0e-9 + 1e-16, 5.0e-9), {"a", "b"}),
    # printed apart (2.0e-17, 6.1e-17) but rounding: nobody is best
    ((2.0e-17, 6.1e-17, 4.0e-17), set()),
    # beyond the resolution: the smallest alone
    ((1.0e-9, 2.0e-9, 3.0e-9), {"a"}),
])
def test_best_is_marked_only_beyond_the_resolution(errors, best):
    document = {"controllers": {name: metrics(constraint_error_max_m=error)
                                for name, error in zip("abc", errors)},
                "joint_velocity_reference": None}
    assert best_rows(document)["constraint_error_max_m"] == best


def test_a_log_axis_starts_at_the_measures_resolution_not_at_rounding():
    """A curve of rounding down to 1e-30 under a signal of 1e-3: the axis shows 1e-12 up,
    whatever matplotlib's autoscale chose."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from teleop.experiments.plots import LOG_FLOOR, log_floor

    fig, axis = plt.subplots()
    axis.semilogy(np.arange(4), [1e-30, 1e-17, 1e-6, 1e-3])
    assert axis.get_ylim()[0] < 1e-29  # what the autoscale shows: rounding
    log_floor(axis, LOG_FLOOR)
    low, high = axis.get_ylim()
    assert low == LOG_FLOOR and high >= 1e-3
    axis.cla()
    axis.semilogy(np.arange(2), [1e-30, 1e-20])  # nothing above the floor: a decade shown
    log_floor(axis, LOG_FLOOR)
    assert axis.get_ylim() == (LOG_FLOOR, 10 * LOG_FLOOR)
    plt.close(fig)


def test_many_distinct_failure_messages_are_all_counted_the_rest_together():
    """25 distinct messages over 30 failed steps (and ok steps between): the 20 most
    frequent kept, the 5 others counted in one entry; every failed step in a count."""
    from controllers.step_message import StepMessage
    from teleop.experiments.compare import MAX_FAILURE_MESSAGES, summarise_failures
    from teleop.loop import StepRecord

    def record(t: float, failed: bool, message: str) -> StepRecord:
        empty = np.zeros(0)
        return StepRecord(t, 0.0, 0.0, 0.0, np.zeros(1), np.zeros(1), 0.0, failed, 0.0, 0.0,
                          0.0, False, empty, (), empty, np.zeros((1, 3)), np.zeros((1, 3)),
                          np.zeros((1, 3)), empty, (), step_message=StepMessage.worded(message))

    messages = [f"m{k}" for k in range(25)] + ["m0"] * 3 + ["m1"] * 2  # 30 failures
    records = []
    for k, message in enumerate(messages):
        records += [record(2 * k * 1e-3, False, ""), record((2 * k + 1) * 1e-3, True, message)]
    summary = summarise_failures(records)
    assert len(summary) == MAX_FAILURE_MESSAGES + 1
    assert summary[0] == {"message": "m0", "count": 4, "first_step": 1, "first_t_s": 1e-3}
    assert summary[1]["message"] == "m1" and summary[1]["count"] == 3
    assert sum(entry["count"] for entry in summary) == 30
    assert summary[-1]["message"] == "5 other messages" and summary[-1]["count"] == 5
    assert summary[-1]["first_step"] == 2 * 20 + 1  # m20, the first of the others
