"""The step's message worded when read (issue 37 item 2; docs/design.md 8.3 and 16).

The loop keeps every period's message as a :class:`~controllers.step_message.StepMessage`
and words it only when a reader asks, the supervisor's words too. The reference is the
eager text of a first run read at once: the controller's ``info.message`` (or the loop's
refusal) and the supervisor's words read right after each period, composed into the
loop's message as the loop wrote it before (written out in this file: the status, the
measured breach, the supervisor's words, the controller's). A second run of the same
periods is read only after it ended: every record's text must equal the first's, on
scenarios covering every status: ``ok``, ``scaled``, ``least_squares`` (with the
analytical form's hand-over to the general form), ``constraint_degraded``, ``failed`` and
the supervisor scaling and holding the target.
"""

from __future__ import annotations

import collections
import math
from typing import Callable

import numpy as np
import pinocchio as pin
import pytest

from constraints import Hole
from controllers.cjm import controller as cjm_controller
from controllers.cjm.report import solve_info
from controllers.step_message import StepMessage
from teleop import load_robot
from teleop.controller_specs import ROBOT, make_controller
from teleop.experiments.scenarios import load_scenario
from teleop.loop import LoopConfig, StepRecord, Supervision, TeleopLoop
from teleop.loop.supervisor import SupervisorConfig
from teleop.plants.choice import PlantChoice
from teleop.plants.imperfect import Imperfections

#: a supervisor that finds a noisy encoder's errors beyond tolerance (10 um) now and then,
#: and scales (from 20 um) and holds (from 40 um) the operator's motion quickly
TIGHT = SupervisorConfig(tolerance=1e-5, error_warn=2e-5, error_hold=4e-5, fall_time=0.02,
                         release_time=0.03)


def loop_message(supervision: Supervision, status: str, message: str) -> str:
    """The loop's message as it was worded at once: the controller's message and the
    supervisor's words within tolerance; beyond it what was measured, what the
    supervisor did and, unless ``ok``, what the controller said."""
    if not supervision.breach:
        if not supervision.words:
            return message
        return f"{message}; {supervision.words}" if message else supervision.words
    text = f"measured: {supervision.breach}"
    if supervision.words:
        text = f"{text}; {supervision.words}"
    if status != "ok":
        text = f"{text}; controller: {status}" + (f", {message}" if message else "")
    return text


def run_and_read_late(make_loop: Callable[[], TeleopLoop],
                      targets: list) -> tuple[list[StepRecord], list[str], list[str]]:
    """Two loops from ``make_loop`` over ``targets`` (deterministic: the same periods).
    The first is read at once: per period the controller's status and the loop's message
    worded then (:func:`loop_message` of the controller's and the supervisor's words read
    right after the period; the record's own text too). The second's records, returned
    with those statuses and texts, are read by the caller after the whole run."""
    eager_loop, statuses, eager = make_loop(), [], []
    for target in targets:
        record = eager_loop.tick(target)
        info = eager_loop.controller.info
        status, message = info.status.value, info.message
        if eager_loop.refused:  # the controller refused the input: the loop's stop says why
            status, message = "failed", eager_loop.refused
        statuses.append(status)
        eager.append(loop_message(eager_loop.supervision, status, message))
        assert record.message == eager[-1]
    late_loop = make_loop()
    return [late_loop.tick(target) for target in targets], statuses, eager


def scenario_run(name: str, spec: str, acceleration_limits: bool, compiled_tick: bool,
                 config: LoopConfig, periods: int) -> tuple[list[StepRecord], list[str],
                                                          list[str]]:
    """:func:`run_and_read_late` on scenario ``name`` with controller ``spec``."""
    plan = load_scenario(name)

    def make_loop() -> TeleopLoop:
        controller = make_controller(spec, plan.robot, plan.make_constraints(), dt=config.dt,
                                     acceleration_limit=ROBOT if acceleration_limits else None)
        return TeleopLoop(plan.robot, controller, q0=plan.q0, config=config,
                          compiled_tick=compiled_tick)

    return run_and_read_late(make_loop,
                             [plan.target((i + 1) * config.dt) for i in range(periods)])


def check_late_equals_eager(records: list[StepRecord], statuses: list[str],
                            eager: list[str]) -> collections.Counter:
    """Every record's controller status and message (read now) are the eager ones; the
    loop's status counts."""
    for index, (record, status, text) in enumerate(zip(records, statuses, eager)):
        assert record.controller_status == status, index
        assert record.message == text, (index, record.message, text)
    return collections.Counter(record.status for record in records)


@pytest.mark.parametrize("spec, compiled_tick", [("cjm", True), ("cjm", False),
                                                  ("cjm:python", False), ("qp:daqp", False)])
def test_fast_lateral_with_acceleration_limits_words_the_same_when_read_late(
        spec: str, compiled_tick: bool) -> None:
    """``fast-lateral`` with the robot's acceleration limits, 1.2 s: ``ok``, ``scaled``
    and ``least_squares`` steps (the CJM's joints at a limit, the damping near a
    singularity, the analytical form handing over to the general form)."""
    records, statuses, eager = scenario_run("fast-lateral", spec, True, compiled_tick,
                                            LoopConfig(), 1200)
    counts = check_late_equals_eager(records, statuses, eager)
    assert counts["least_squares"] > 100 and counts["ok"] > 100, counts
    if spec.startswith("cjm"):
        assert any(text.startswith("pre-constraint chain singular") for text in eager)
        assert any("at a limit" in text for text in eager)


def test_scaled_steps_word_the_same_when_read_late() -> None:
    """``fast-lateral`` without acceleration limits: the task scaled to a joint's limit."""
    records, statuses, eager = scenario_run("fast-lateral", "cjm", False, True, LoopConfig(),
                                            1500)
    counts = check_late_equals_eager(records, statuses, eager)
    assert counts["scaled"] > 100, counts
    assert any("task scaled to" in text for text in eager)


@pytest.mark.parametrize("compiled_tick", [True, False])
def test_the_supervisor_scaling_holding_and_releasing_words_the_same_when_read_late(
        compiled_tick: bool) -> None:
    """``fast-lateral`` with acceleration limits behind a 1e-3 rad encoder noise (the
    kinematic plant), its hole measured 0.4-40 um off at the sensed configuration, under a
    supervisor that flags 10 um, scales from 20 um and holds from 40 um: the loop's
    ``constraint_degraded`` with the breach, the scale falling, the target held, released,
    and its offset kept as a clutch's within tolerance (the supervisor's words after the
    controller's)."""
    plan = load_scenario("fast-lateral")
    config = LoopConfig(supervisor=TIGHT)

    def make_loop() -> TeleopLoop:  # the noise seeded: the same run each time
        controller = make_controller("cjm", plan.robot, plan.make_constraints(), dt=config.dt,
                                     acceleration_limit=ROBOT)
        plant = PlantChoice().make(plan.robot, config.dt, Imperfections(encoder_noise=1e-3))
        return TeleopLoop(plan.robot, controller, q0=plan.q0, config=config, plant=plant,
                          compiled_tick=compiled_tick)

    records, statuses, eager = run_and_read_late(
        make_loop, [plan.target((i + 1) * config.dt) for i in range(1000)])
    counts = check_late_equals_eager(records, statuses, eager)
    actions = collections.Counter(record.supervisor_action for record in records)
    assert min(actions["none"], actions["scaled"], actions["held"]) > 20, actions
    assert counts["constraint_degraded"] > 100 and counts["least_squares"] > 100, counts
    assert any("target held" in text and "controller: least_squares" in text for text in eager)
    assert any(text.endswith("(kept, as a clutch)") and not text.startswith("measured")
               for text in eager)
    assert any(text.startswith("supervisor releasing") for text in eager)


@pytest.mark.parametrize("spec", ["cjm", "cjm:python"])
def test_degraded_and_failed_steps_word_the_same_when_read_late(spec: str) -> None:
    """A hole 2 cm off the shaft under a 1e-3 rad/s^2 acceleration limit: the correction
    cannot fit (``constraint_degraded``, the supervisor measuring 20 mm); every 7th target
    not finite: the controller refuses it (``failed``, the loop's stop says why) and the
    pose servo starts over, so the period after is a first one, with no feed-forward from
    the refused target (docs/design.md 5.1), and not refused."""
    robot = load_robot("sda10f")
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.05)
    hole.center = hole.center + np.array([0.0, 0.02, 0.0])

    def make_loop() -> TeleopLoop:
        controller = make_controller(spec, robot, [hole],
                                     acceleration_limit=np.full(robot.nv, 1e-3))
        return TeleopLoop(robot, controller, q0=q)

    home = make_loop().ee_placement()
    broken = pin.SE3(home.rotation, np.full(3, math.nan))
    targets = [broken if i % 7 == 6 else home for i in range(60)]
    records, statuses, eager = run_and_read_late(make_loop, targets)
    check_late_equals_eager(records, statuses, eager)
    controller_counts = collections.Counter(statuses)
    assert controller_counts["constraint_degraded"] > 30, controller_counts
    # the refused periods alone: the one after each starts the servo over, not refused
    assert controller_counts["failed"] == 8, controller_counts
    assert [i for i, status in enumerate(statuses) if status == "failed"] == \
        [i for i in range(60) if i % 7 == 6]
    assert all(record.status in ("constraint_degraded", "failed") for record in records)
    assert any("controller: constraint_degraded" in text for text in eager)
    assert any("controller: failed" in text for text in eager)


def test_a_message_is_worded_once_and_only_when_read() -> None:
    calls = []

    def word() -> str:
        calls.append(1)
        return "joint 3 at a limit"

    unread, read = StepMessage(word), StepMessage(word)
    assert not calls
    assert read.text == "joint 3 at a limit" and str(read) == "joint 3 at a limit"
    assert read.text == "joint 3 at a limit" and len(calls) == 1
    assert StepMessage.worded("as written").text == "as written"
    del unread
    assert len(calls) == 1


def test_the_compiled_tick_words_no_message_nobody_reads(monkeypatch) -> None:
    """``fast-lateral`` with acceleration limits through ``advance`` (the hot path): no
    period's report is worded; read afterwards, each is its report's ``solve_info``."""
    words = []
    report_message = cjm_controller.report_message

    def counted(report, joint_names) -> str:
        words.append(report)
        return report_message(report, joint_names)

    monkeypatch.setattr(cjm_controller, "report_message", counted)
    plan = load_scenario("fast-lateral")
    controller = make_controller("cjm", plan.robot, plan.make_constraints(),
                                 acceleration_limit=ROBOT)
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0)
    steps, reports = [], []
    for i in range(400):
        steps.append(loop.advance(plan.target((i + 1) * 1e-3)))
        reports.append(controller.report)
    assert loop.compiled is not None and not words
    texts = [step.message for step in steps]
    assert len(words) == len(steps)
    assert texts == [solve_info(report, controller.joint_names).message for report in reports]
    assert sum(bool(text) for text in texts) > 100
