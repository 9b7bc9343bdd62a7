"""``sleep_until`` (teleop/sleep_until.py): asleep to an absolute deadline on
``time.monotonic``'s clock, never waking before it, a signal handled on the way included.
Only "not before the deadline" is asserted (how late it wakes is the machine's)."""

from __future__ import annotations

import math
import signal
import time

import pytest

from teleop.sleep_until import sleep_until


def test_it_never_wakes_before_its_deadline():
    deadline = time.monotonic()
    for _ in range(200):
        deadline += 1e-3
        sleep_until(deadline)
        assert time.monotonic() >= deadline


def test_a_deadline_already_past_returns():
    before = time.monotonic()
    sleep_until(before - 10.0)
    sleep_until(0.0)
    assert time.monotonic() >= before


def test_a_signal_during_the_sleep_is_handled_and_the_sleep_goes_on_to_its_deadline():
    """SIGALRM 20 ms into a sleep of 200 ms: its Python handler runs, the sleep does not
    end there (clock_nanosleep's EINTR goes back to sleep to the same deadline)."""
    handled: list[float] = []
    previous = signal.signal(signal.SIGALRM, lambda *_: handled.append(time.monotonic()))
    try:
        deadline = time.monotonic() + 0.2
        signal.setitimer(signal.ITIMER_REAL, 0.02)
        sleep_until(deadline)
        woke = time.monotonic()
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, previous)
    assert len(handled) == 1 and handled[0] < deadline <= woke


@pytest.mark.parametrize("deadline", [math.nan, math.inf, -math.inf, "1.0", None, True])
def test_a_deadline_that_is_not_a_finite_number_is_refused_by_name(deadline):
    with pytest.raises(ValueError, match="deadline must be a finite number of seconds"):
        sleep_until(deadline)


@pytest.mark.parametrize("deadline", [2.0**63, 1.9e19, 1e300])
def test_a_deadline_past_the_timespec_range_is_refused_by_name(deadline):
    """A deadline whose seconds do not fit the C ``long`` of ``struct timespec`` wrapped:
    2**63 s returned at once (before its deadline), 1.9e19 s slept 5.5e17 s (a hang)."""
    with pytest.raises(ValueError, match="deadline must be a finite number of seconds"):
        sleep_until(deadline)
