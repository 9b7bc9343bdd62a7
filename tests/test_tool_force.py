"""Force at the tool (issue 36, docs/design.md section 21), its laws without a plant: the
laws' stability bounds against simulations written here, the admittance's rest against
M a + D v + K x = F solved by hand, the tare's mean, and bad tissues, sensors and laws
refused by name. On the MuJoCo plant (the tissue's force, the sensor, the ``palpation``
and ``retraction-y`` targets): tests/test_plant_tool_force.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from teleop.loop.admittance import Admittance
from teleop.loop.force_stability import GAIN_MARGIN, force_loop_bound
from teleop.loop.hybrid_force_motion import HybridForceMotion
from teleop.loop.sensor_tare import SensorTare
from teleop.loop.tool_wrench import tool_wrench
from teleop.plants import Imperfections, MujocoPlant
from teleop.plants.tissue import DEFAULT_TISSUE_STIFFNESS, TissueSurface

DT = 1e-3


def test_without_a_sensor_the_laws_input_is_refused_by_name(sda10f):
    with pytest.raises(ValueError, match="kinematic plant has no force/torque sensor"):
        tool_wrench(None, 0)
    with pytest.raises(ValueError, match="ImperfectPlant has no force/torque sensor"):
        tool_wrench(Imperfections(encoder_noise=1e-3).plant(sda10f.model, DT), 0)
    with pytest.raises(ValueError, match="senses no wrench at EE 0"):
        tool_wrench(MujocoPlant(sda10f, DT), 0)


@pytest.mark.parametrize("options, match", [
    ({"point": [0, 0], "normal": [0, 0, 1]}, "point"),
    ({"point": [0, 0, 0], "normal": [0, 0, 0]}, "normal"),
    ({"point": [0, 0, 0], "normal": [0, np.nan, 1]}, "normal"),
    ({"point": [0, 0, 0], "normal": [0, 0, 1], "stiffness": 0.0}, "stiffness"),
    ({"point": [0, 0, 0], "normal": [0, 0, 1], "damping": -1.0}, "damping"),
    ({"point": [0, 0, 0], "normal": [0, 0, 1], "stiffness": "1"}, "stiffness"),
])
def test_bad_tissues_are_refused_naming_the_field(options, match):
    with pytest.raises(ValueError, match=match):
        TissueSurface(**options)


def test_bad_sensor_and_law_settings_are_refused_by_name(sda10f):
    with pytest.raises(ValueError, match="sensor_bias"):
        MujocoPlant(sda10f, DT, sensor_bias=[0.0] * 5)
    with pytest.raises(ValueError, match="sensor_noise"):
        MujocoPlant(sda10f, DT, sensor_noise=-1.0)
    with pytest.raises(ValueError, match="force_axes"):
        HybridForceMotion((False, False, False), (0, 0, 1), 1.0, 100.0, DT)
    with pytest.raises(ValueError, match="setpoint"):
        HybridForceMotion((False, False, True), (0, 0, np.inf), 1.0, 100.0, DT)
    law = HybridForceMotion((False, False, True), (0, 0, 1), 1.0, 100.0, DT)
    with pytest.raises(ValueError, match="wrench is not finite"):
        law.twist(np.zeros(6), np.full(6, np.nan))


def _delayed_integrator_grows(gain: float, delay: int, steps: int = 4000) -> bool:
    """``f_{n+1} = f_n + g (1 - f_{n-d})`` simulated: does the error grow?"""
    history = [0.0] * (delay + 1)
    for _ in range(steps):
        history.append(history[-1] + gain * (1.0 - history[-1 - delay]))
    return abs(1.0 - history[-1]) > 1.0


@pytest.mark.parametrize("delay", [0, 1, 2, 3])
def test_the_force_loop_bound_is_where_the_sampled_loop_turns_unstable(delay):
    bound = force_loop_bound(delay)
    assert not _delayed_integrator_grows(0.98 * bound, delay)
    assert _delayed_integrator_grows(1.02 * bound, delay)


def test_a_force_gain_beyond_the_margin_is_refused_naming_it():
    stiffness = 500.0
    allowed = force_loop_bound(2) / GAIN_MARGIN / (stiffness * DT)
    HybridForceMotion((False, False, True), (0, 0, 1), 0.99 * allowed, stiffness, DT)
    with pytest.raises(ValueError, match="force_gain .* unstable against a contact of 500"):
        HybridForceMotion((False, False, True), (0, 0, 1), 1.01 * allowed, stiffness, DT)


@given(st.floats(0.05, 5.0), st.floats(1.0, 200.0), st.floats(10.0, 2000.0))
def test_an_accepted_admittance_is_stable_and_a_refused_one_is_past_the_margin(mass, damping,
                                                                               stiffness):
    a, b = damping * DT / mass, stiffness * DT * DT / mass
    # the semi-implicit Euler step's matrix on (x, v), written out here
    step = np.array([[1.0 - b, DT * (1.0 - a)], [-stiffness * DT / mass, 1.0 - a]])
    radius = float(np.max(np.abs(np.linalg.eigvals(step))))
    try:
        Admittance(mass, damping, stiffness, 0.0, DT)
    except ValueError as error:
        assert "admittance mass" in str(error)
        assert a > 1.0 or 2.0 * a + b > 2.0
        return
    assert radius < 1.0


def filtered_admittance_radius(mass: float, damping: float, stiffness: float, contact: float,
                               cutoff: float, order: int) -> float:
    """The spectral radius of one period of the admittance against a contact spring, its
    force through the filter, written out here on the state (x, v, the filter's sections)
    and linearised column by column (the step is linear)."""
    pole = math.exp(-2.0 * math.pi * cutoff * DT)

    def step(state: np.ndarray) -> np.ndarray:
        x, v, sections = state[0], state[1], state[2:].copy()
        reading = -contact * x  # the contact's force on the tool where it is
        for i in range(order):
            sections[i] = pole * sections[i] + (1.0 - pole) * reading
            reading = sections[i]
        v = v + DT * (reading - damping * v - stiffness * x) / mass
        return np.concatenate([[x + DT * v, v], sections])

    matrix = np.column_stack([step(column) for column in np.eye(2 + order)])
    return float(np.max(np.abs(np.linalg.eigvals(matrix))))


@given(st.floats(0.05, 5.0), st.floats(1.0, 200.0), st.floats(10.0, 2000.0),
       st.floats(0.0, 5000.0), st.floats(2.0, 200.0), st.sampled_from([1, 2]))
def test_a_filtered_admittance_is_accepted_when_stable_at_half_its_mass(
        mass, damping, stiffness, contact, cutoff, order):
    """The check's margin (docs/design.md 21.3): the loop written out in the test is stable
    at half the mass exactly when the law is accepted; accepted, it is stable as given."""
    margin = filtered_admittance_radius(0.5 * mass, damping, stiffness, contact, cutoff, order)
    assume(abs(margin - 1.0) > 1e-9)  # on the boundary, rounding decides
    try:
        Admittance(mass, damping, stiffness, contact, DT, filter_cutoff=cutoff,
                   filter_order=order)
    except ValueError as error:
        assert "admittance mass" in str(error) and "force filter" in str(error)
        assert margin > 1.0
        return
    assert margin < 1.0
    assert filtered_admittance_radius(mass, damping, stiffness, contact, cutoff, order) < 1.0


def test_the_filter_is_what_makes_a_stiff_contact_unstable():
    """A law the unfiltered check accepts against 5,000 N/m is refused with a 10 Hz filter
    (its lag), and the written-out loop agrees on both (a filter at 1 MHz is none)."""
    law = (1.0, 40.0, 200.0, 5000.0)
    Admittance(*law, DT)
    assert filtered_admittance_radius(0.5, 40.0, 200.0, 5000.0, 1e6, 1) < 1.0
    with pytest.raises(ValueError, match="2-section force filter"):
        Admittance(*law, DT, filter_cutoff=10.0)
    assert filtered_admittance_radius(0.5, 40.0, 200.0, 5000.0, 10.0, 2) > 1.0


@pytest.mark.slow
@settings(deadline=None)  # up to 0.2 s of Python steps per example on a loaded machine
@given(st.floats(0.2, 2.0), st.floats(20.0, 100.0), st.floats(100.0, 500.0),
       st.lists(st.floats(-3.0, 3.0), min_size=3, max_size=3))
def test_the_admittance_rests_at_force_over_stiffness(mass, damping, stiffness, force):
    law = Admittance(mass, damping, stiffness, 0.0, DT)
    wrench = np.concatenate([force, np.zeros(3)])
    # 20 of the slowest time constant (D / K overdamped, 2 M / D underdamped)
    for _ in range(int(20.0 * max(damping / stiffness, 2.0 * mass / damping) / DT)):
        twist = law.twist(np.zeros(6), wrench)
    np.testing.assert_allclose(law.offset, np.asarray(force) / stiffness, atol=1e-6)
    assert np.max(np.abs(twist[:3])) < 1e-6


def test_the_default_tissue_stiffness_is_sneddons_punch():
    # 2 a E / (1 - nu^2), a = 2.5 mm, E = 10 kPa, nu = 0.5
    assert DEFAULT_TISSUE_STIFFNESS == pytest.approx(66.666, rel=1e-4)


def test_the_tare_is_the_mean_of_its_window_and_refuses_bad_readings():
    readings = np.arange(18, dtype=float).reshape(3, 6)
    tare = SensorTare(2)
    tare(readings[0])
    np.testing.assert_allclose(tare(readings[1]), readings[1] - readings[:2].mean(axis=0))
    assert tare.done
    np.testing.assert_allclose(tare(readings[2]), readings[2] - readings[:2].mean(axis=0))
    with pytest.raises(ValueError, match="tare samples"):
        SensorTare(0)
    with pytest.raises(ValueError, match="wrench to tare"):
        tare(np.full(6, np.inf))
