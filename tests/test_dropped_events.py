"""No event of the compiled step is lost silently (issue 34, item 5).

The compiled step records a step's events in a buffer of fixed size (docs/design.md
section 16); an event past its last row is counted in the report's ``dropped_events`` and
the message says how many. The reference is the Python step, whose record has no limit:
on ur5_instrument pushed into eight balls about its tool (one hole, collision rows that
conflict with it), the compiled step given room for ten events records the reference's
first ten, counts the rest, and keeps the reference's status.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from constraints.collision import CollisionAvoidance, Sphere
from controllers import CJMController
from controllers.cjm.compiled import CompiledStep
from controllers.cjm.report import dropped_events_note, report_message
from teleop.experiments.bench_problems import bench_holes

#: the room the overflowing step is given (the reference records more than twice this)
SMALL_CAPACITY = 10


@pytest.fixture(scope="module")
def crowded(ur5_instrument):
    """The two controllers (Python, compiled) with eight 2 cm balls 3 cm about the tool tip
    (a fixed draw), the home configuration and a twist pushing the tip down into them."""
    robot = ur5_instrument
    model = robot.model
    data = model.createData()
    q = robot.q_home.copy()
    pin.framesForwardKinematics(model, data, q)
    tip = data.oMf[model.getFrameId(robot.ee_frames[0])]
    rng = np.random.default_rng(2)
    balls = []
    for _ in range(8):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        balls.append(Sphere(tip.translation + 0.03 * direction
                            + np.array([0.0, 0.0, -0.05 * rng.random()]), 0.02))
    collisions = CollisionAvoidance(robot, balls, self_collision=False)
    twist = np.zeros(6)
    twist[:3] = tip.rotation.T @ np.array([0.3, 0.0, -1.0])
    controllers = [CJMController(robot, constraints=bench_holes(robot), dt=0.001,
                                 backend=backend, collisions=collisions)
                   for backend in ("python", "compiled")]
    return controllers, q, twist


def test_the_default_record_holds_every_event(crowded):
    (python, compiled), q, twist = crowded
    python.solve(q, twist)
    compiled.solve(q, twist)
    expected, actual = python.report, compiled.report
    assert len(expected.events) > 2 * SMALL_CAPACITY
    assert [event for event, *_ in actual.events] == [event for event, *_ in expected.events]
    assert actual.dropped_events == expected.dropped_events == 0
    assert actual.status is expected.status
    assert "not recorded" not in compiled.info.message


def test_events_past_a_full_record_are_counted_and_said(crowded):
    (python, compiled), q, twist = crowded
    python.solve(q, twist)
    expected = python.report
    small = CompiledStep(compiled.step.setup, compiled.data, event_capacity=SMALL_CAPACITY)
    _, report = small.solve(q, twist)
    assert len(report.events) == SMALL_CAPACITY
    for (event, *figures), (reference, *reference_figures) in zip(report.events,
                                                                    expected.events):
        assert event is reference
        np.testing.assert_allclose(figures, reference_figures, rtol=1e-6, atol=1e-9)
    assert report.dropped_events == len(expected.events) - SMALL_CAPACITY
    bound = small.pipeline.step.report  # the C++ report, read by name
    assert (bound.event_count, bound.dropped_event_count) == (SMALL_CAPACITY, report.dropped_events)
    assert report.status is expected.status
    message = report_message(report, python.joint_names)
    assert message.endswith(dropped_events_note(report.dropped_events))
    assert f"{report.dropped_events} more events not recorded" in message


@pytest.mark.parametrize("capacity", [0, -2])
def test_a_record_without_room_is_refused(crowded, capacity):
    (_, compiled), _, _ = crowded
    with pytest.raises(ValueError, match="event_capacity"):
        CompiledStep(compiled.step.setup, compiled.data, event_capacity=capacity)
