"""Hypothesis strategies shared by the property-based tests."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)
vec3 = arrays(float, 3, elements=finite)
unit3 = vec3.filter(lambda v: np.linalg.norm(v) > 0.1).map(lambda v: v / np.linalg.norm(v))


@st.composite
def placements(draw) -> pin.SE3:
    """A random rigid placement: rotation about a random axis, translation in [-1, 1]^3."""
    axis = draw(unit3)
    angle = draw(st.floats(-np.pi, np.pi))
    return pin.SE3(pin.exp3(angle * axis), draw(vec3))
