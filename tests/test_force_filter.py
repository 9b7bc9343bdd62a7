"""The low-pass filter on the sensed wrench (issue 36, docs/design.md 21.3): its step
response against the closed forms written here, the force loop's stability bound with
the filter's lag against the sampled loop simulated here, the law refusing a cut-off whose
lag leaves its gain past the margin, and what the filter does to palpation with sensor
noise (jerk, force error)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from teleop.experiments.palpation import run_palpation
from teleop.loop.force_stability import GAIN_MARGIN, force_loop_bound
from teleop.loop.hybrid_force_motion import HybridForceMotion
from teleop.loop.wrench_filter import WrenchLowPass
from teleop.plants.tissue import DEFAULT_TISSUE_STIFFNESS

DT = 1e-3


@given(st.floats(0.5, 400.0), st.sampled_from([1, 2]))
def test_the_step_response_is_the_closed_form(cutoff, order):
    low_pass = WrenchLowPass(cutoff, DT, order)
    beta = math.exp(-2.0 * math.pi * cutoff * DT)
    alpha = 1.0 - beta
    assert low_pass.pole == pytest.approx(beta, rel=1e-15)
    np.testing.assert_array_equal(low_pass(np.zeros(6)), 0.0)  # starts at the first reading
    step = np.array([1.0, -2.0, 0.5, 0.0, 3.0, -1.0])
    for n in range(1, 60):
        # one section: 1 - beta^n; two: 1 - beta^n (1 + alpha n) (the z-transform's inverse)
        expected = 1.0 - beta ** n * (1.0 if order == 1 else 1.0 + alpha * n)
        np.testing.assert_allclose(low_pass(step), expected * step, atol=1e-12)


def _filtered_loop_grows(gain: float, delay: int, cutoff: float, order: int,
                         steps: int = 6000) -> bool:
    """``f_{n+1} = f_n + g (1 - y_{n-d})``, ``y`` the force through ``order`` sections
    ``y_n = y_{n-1} + alpha (f_n - y_{n-1})``, simulated: does the error grow?"""
    alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff * DT)
    sections = [0.0] * order
    force, filtered = 0.0, [0.0] * (delay + 1)
    for _ in range(steps):
        value = force
        for i in range(order):
            sections[i] += alpha * (value - sections[i])
            value = sections[i]
        filtered.append(value)
        force += gain * (1.0 - filtered[-1 - delay])
    return abs(1.0 - force) > 1.0


@pytest.mark.parametrize("delay, cutoff, order", [
    (1, 20.0, 1), (2, 20.0, 1), (2, 20.0, 2), (2, 50.0, 2), (3, 10.0, 2), (1, 100.0, 2)])
def test_the_bound_with_the_filter_is_where_the_sampled_loop_turns_unstable(delay, cutoff,
                                                                           order):
    pole = math.exp(-2.0 * math.pi * cutoff * DT)
    bound = force_loop_bound(delay, pole, order)
    assert not _filtered_loop_grows(0.98 * bound, delay, cutoff, order)
    assert _filtered_loop_grows(1.02 * bound, delay, cutoff, order)
    assert bound < force_loop_bound(delay)  # the lag lowers it


def test_the_law_refuses_a_cutoff_whose_lag_leaves_the_gain_past_the_margin():
    """palpation's gain (1 (m/s)/N on 66.7 N/m: g = 0.067) with two periods of delay is
    inside half the bound with a 20 Hz filter, not with a 10 Hz one."""
    gain = 1.0 * DEFAULT_TISSUE_STIFFNESS * DT
    assert gain < force_loop_bound(2, math.exp(-2.0 * math.pi * 20.0 * DT), 2) / GAIN_MARGIN
    assert gain > force_loop_bound(2, math.exp(-2.0 * math.pi * 10.0 * DT), 2) / GAIN_MARGIN
    HybridForceMotion((False, False, True), (0, 0, 1), 1.0, DEFAULT_TISSUE_STIFFNESS, DT,
                      filter_cutoff=20.0)
    with pytest.raises(ValueError, match="force_gain 1.0 .* force filter of pole 0.9391"):
        HybridForceMotion((False, False, True), (0, 0, 1), 1.0, DEFAULT_TISSUE_STIFFNESS, DT,
                          filter_cutoff=10.0)


@pytest.mark.parametrize("options, match", [
    ({"cutoff": 0.0}, "filter cutoff"), ({"cutoff": 500.0}, "Nyquist"),
    ({"cutoff": float("nan")}, "filter cutoff"), ({"cutoff": 10.0, "order": 3}, "order"),
])
def test_bad_filters_are_refused_by_name(options, match):
    with pytest.raises(ValueError, match=match):
        WrenchLowPass(dt=DT, **options)
    low_pass = WrenchLowPass(10.0, DT)
    with pytest.raises(ValueError, match="not finite"):
        low_pass(np.full(6, np.inf))


@pytest.mark.slow
def test_the_filter_takes_the_sensor_noise_out_of_the_jerk():
    """0.01 N of sensor noise: unfiltered, the force loop passes it to the command (jerk
    6.3e5 rad/s^3); through the 20 Hz two-section filter the jerk is below a fiftieth of
    that (measured 6.2e3), the force error stays within 5 mN RMS."""
    raw = run_palpation("cjm", sensor_noise=0.01, seed=1)
    filtered = run_palpation("cjm", sensor_noise=0.01, seed=1, force_filter=20.0)
    assert filtered.jerk_max < raw.jerk_max / 50.0
    assert filtered.force_error_rms <= 5e-3 and filtered.contact_lost == 0
    assert filtered.hole_error_max <= 1e-4 and filtered.port_force_max <= 0.2
