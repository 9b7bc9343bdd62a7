"""A constraint's gain set after construction goes through the checks of construction.

The reference is construction itself: a constraint built with gain ``K`` and handed to a
controller at period ``dt`` either is refused (a ``ValueError`` with a message) or runs. The
same gain set on a constraint the controller already holds must give the same message, at
once (``K dt`` out of the stable range of docs/design.md section 3 included), or the same
command as the constraint built with it.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from constraints import Barrier, Hole, Plane, PointLock
from controllers import CJMController, QPController

#: a constraint of each kind on the constrained link of a robot at home, given its gain
KINDS = {
    "hole": lambda robot, gain: Hole.on_link(robot, robot.q_home, 0.08, gain=gain),
    "plane": lambda robot, gain: Plane.through_link_point(
        robot, robot.q_home, normal=[0.0, 0.0, 1.0], distance=0.08, gain=gain),
    "barrier": lambda robot, gain: Barrier.through_link_point(
        robot, robot.q_home, normal=[0.0, 0.0, 1.0], distance=0.08, gain=gain),
    "point_lock": lambda robot, gain: PointLock.on_link(robot, robot.q_home, distance=0.08,
                                                        gain=gain),
}
#: a gain every kind takes at every period drawn (K dt <= 0.1)
STABLE_GAIN = 10.0
TWIST = np.array([0.01, -0.02, 0.005, 0.02, 0.0, -0.01])

gains = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1e4, 1e5),
    st.integers(-10**6, 10**6),
    st.sampled_from([True, False, "abc", "100", [100.0], {"gain": 1}, 1 + 2j, 10**400]),
)


def outcome(action) -> tuple[str, object]:
    """``("error", message)`` when ``action`` raises ``ValueError``, else ``("ok", result)``."""
    try:
        return "ok", action()
    except ValueError as error:
        return "error", str(error)


@settings(max_examples=60, deadline=None)
@given(kind=st.sampled_from(sorted(KINDS)), gain=gains,
       rate=st.sampled_from([100.0, 1000.0, 10000.0]),
       controller_type=st.sampled_from([CJMController, QPController]))
def test_a_gain_set_later_meets_the_checks_of_construction(sda10f, kind, gain, rate,
                                                           controller_type):
    make = KINDS[kind]
    dt = 1.0 / rate

    def built_with_the_gain():
        controller = controller_type(sda10f, [make(sda10f, gain)], dt=dt)
        return controller.solve(sda10f.q_home, TWIST)

    constraint = make(sda10f, STABLE_GAIN)
    controller = controller_type(sda10f, [constraint], dt=dt)
    controller.solve(sda10f.q_home, TWIST)  # a step at the first gain (compiled: its terms sent)

    def set_later():
        constraint.gain = gain  # refused at once, or taken
        return controller.solve(sda10f.q_home, TWIST)

    expected, later = outcome(built_with_the_gain), outcome(set_later)
    assert later[0] == expected[0], (expected, later)
    if expected[0] == "error":
        assert later[1] == expected[1]
        assert "gain" in later[1]
    else:
        scale = 1.0 + float(np.max(np.abs(expected[1])))
        np.testing.assert_allclose(later[1], expected[1], rtol=0.0, atol=1e-12 * scale)


def test_an_unstable_gain_is_refused_at_once_and_changes_nothing(sda10f):
    """Finding 5: ``hole.gain = -500`` after construction is refused at once, and so is
    5000 1/s at 1 kHz (K dt = 5): the gain stays, the next step is the one before."""
    hole = KINDS["hole"](sda10f, 100.0)
    controller = CJMController(sda10f, [hole])
    before = controller.solve(sda10f.q_home, TWIST)
    with pytest.raises(ValueError, match=r"^gain must be >= 0, got -500$"):
        hole.gain = -500
    assert hole.gain == 100.0
    with pytest.raises(ValueError, match=r"Hole gain 5000 1/s is unstable at 1000 Hz \(K dt = 5"):
        hole.gain = 5000.0
    assert hole.gain == 100.0
    np.testing.assert_array_equal(controller.solve(sda10f.q_home, TWIST), before)
    hole.gain = 150.0
    reference = CJMController(sda10f, [KINDS["hole"](sda10f, 150.0)])
    np.testing.assert_array_equal(controller.solve(sda10f.q_home, TWIST),
                                  reference.solve(sda10f.q_home, TWIST))
