"""A port force's magnitude has one arithmetic (``teleop.plants.largest_force``): the
plant's measure of a period (``PlantMeasures.port_force``) and the UI's plot of the largest
per sample (``web.app.trace.Trace.feel_port_forces``) agree bit for bit, so that the plot's
peak is never above every period's measure (tests/test_browser_plant.py compares them; two
fresh clones failed there by one ulp when each computed the norm its own way)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from teleop.plants import PlantMeasures, largest_force
from web.app.trace import Trace

force_rows = arrays(np.float64, st.tuples(st.integers(1, 4), st.just(3)),
                    elements=st.floats(-1e3, 1e3, allow_subnormal=False))


@given(forces=force_rows)
def test_the_plot_s_peak_is_the_plant_s_measure_bit_for_bit(forces: np.ndarray):
    measures = PlantMeasures(forces, np.zeros(len(forces)), 0.0, False)
    trace = Trace()
    trace.feel_port_forces(forces)
    assert trace._port_peak == measures.port_force
    # and the magnitude itself, against the norm computed in the test in long double
    exact = max(math.sqrt(sum(float(np.longdouble(x) ** 2) for x in row)) for row in forces)
    assert measures.port_force == np.float64(exact) or math.isclose(
        measures.port_force, exact, rel_tol=4 * np.finfo(float).eps)


@given(first=force_rows, second=force_rows)
def test_the_plot_keeps_the_largest_of_the_periods_since_its_last_sample(
        first: np.ndarray, second: np.ndarray):
    trace = Trace()
    trace.feel_port_forces(first)
    trace.feel_port_forces(second)
    assert trace._port_peak == max(largest_force(first), largest_force(second))


def test_no_port_is_no_force_and_a_nan_force_is_nan():
    assert largest_force(np.zeros((0, 3))) == 0.0
    assert math.isnan(largest_force(np.array([[1.0, math.nan, 0.0], [2.0, 0.0, 0.0]])))
