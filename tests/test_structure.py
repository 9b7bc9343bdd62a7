"""Structure matrices S of every constraint type against an independent null space."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
from hypothesis import given, settings
from hypothesis import strategies as st
from strategies import placements, unit3, vec3

from constraints import (
    Barrier,
    Hole,
    Plane,
    PointLock,
    structure_nullspace,
    structure_paper,
)


@st.composite
def constraints(draw):
    """Any constraint type on a link called 'link', with random geometry."""
    kind = draw(st.sampled_from(["hole", "plane", "barrier", "point"]))
    if kind == "hole":
        return Hole("link", draw(vec3), link_axis=draw(unit3))
    if kind == "point":
        return PointLock("link", draw(vec3), draw(vec3))
    cls = Plane if kind == "plane" else Barrier
    return cls("link", draw(vec3), draw(vec3), draw(unit3))


def point_velocity_rows(p: np.ndarray, C: np.ndarray) -> np.ndarray:
    """``C [I, -hat(p)]``: maps V_a to the constrained velocity of the point."""
    return C @ np.hstack([np.eye(3), -pin.skew(p)])


def assert_spans_nullspace(S: np.ndarray, p: np.ndarray, C: np.ndarray) -> None:
    M = point_velocity_rows(p, C)
    k = C.shape[0]
    reference = scipy.linalg.null_space(M)  # independent: SciPy's SVD null space
    assert reference.shape[1] == 6 - k
    assert S.shape == (6, 6 - k)
    assert np.linalg.matrix_rank(S, tol=1e-9) == 6 - k  # full column rank
    np.testing.assert_allclose(M @ S, 0.0, atol=1e-12)  # inside the null space...
    # ...and the same subspace: projecting S onto the reference basis loses nothing.
    np.testing.assert_allclose(reference @ (reference.T @ S), S, atol=1e-12)


@settings(max_examples=300, deadline=None)
@given(constraint=constraints(), placement=placements())
def test_structure_spans_the_null_space_of_the_constraint_rows(constraint, placement):
    state = constraint.evaluate(placement)
    assert np.allclose(state.C @ state.C.T, np.eye(constraint.dim), atol=1e-12)
    S = constraint.structure(placement)
    assert_spans_nullspace(S, state.p, state.C)


@settings(max_examples=300, deadline=None)
@given(p=vec3, axis=unit3, k=st.integers(1, 3), angle=st.floats(-np.pi, np.pi))
def test_nullspace_structure_for_random_p_and_C(p, axis, k, angle):
    C = pin.exp3(angle * axis)[:k]  # k orthonormal rows of a random rotation
    assert_spans_nullspace(structure_nullspace(p, C), p, C)


@settings(max_examples=300, deadline=None)
@given(a=st.floats(0.01, 1.0), axis=unit3, k=st.integers(1, 2), angle=st.floats(-np.pi, np.pi))
def test_paper_structure_spans_the_same_space(a, axis, k, angle):
    # constrained directions perpendicular to p, as in the paper's plane and hole
    basis = np.vstack([axis, np.cross(axis, [1.0, 0.3, -0.2])])
    basis[1] /= np.linalg.norm(basis[1])
    rotation = pin.exp3(angle * axis)
    C = (rotation @ np.vstack([basis[1], np.cross(axis, basis[1])]).T).T[:k]
    p = a * axis
    S_paper = structure_paper(p, C)
    assert_spans_nullspace(S_paper, p, C)
    S_free = structure_nullspace(p, C)
    # same column space
    np.testing.assert_allclose(S_free @ np.linalg.lstsq(S_free, S_paper, rcond=None)[0],
                               S_paper, atol=1e-9)


def test_paper_hole_form_is_equation_13():
    """Link axis z, p = a e_z: V_a = [v1, v2, v_z, v2/a, -v1/a, w_z] (eq 13, corrected)."""
    a = 0.3
    C = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    S = structure_paper(np.array([0, 0, a]), C)
    v1, v2, vz, wz = 0.2, -0.7, 0.4, 1.1
    np.testing.assert_allclose(S @ [v1, v2, vz, wz], [v1, v2, vz, v2 / a, -v1 / a, wz])


def test_paper_plane_form_is_equation_10():
    """No motion along y at p = a e_z: v_y = v1, w_x = v1 / a (eqs 9-10)."""
    a = 0.25
    S = structure_paper(np.array([0, 0, a]), np.array([[0, 1.0, 0]]))
    v1 = 0.3
    twist = S @ np.array([v1, 0, 0, 0, 0])
    np.testing.assert_allclose(twist, [0, v1, 0, v1 / a, 0, 0])


def test_nullspace_structure_is_well_conditioned_where_the_paper_form_is_singular():
    C = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    conditions = [np.linalg.cond(structure_nullspace(np.array([0, 0, a]), C))
                  for a in (0.0, 1e-6, 0.1, 0.5)]
    assert max(conditions) < 2.0
    assert np.linalg.cond(structure_paper(np.array([0, 0, 1e-6]), C)) > 1e5
    with pytest.raises(ValueError, match="a = 0"):
        structure_paper(np.zeros(3), C)
    with pytest.raises(ValueError, match="perpendicular"):
        structure_paper(np.array([0, 0, 0.1]), np.array([[0, 0, 1.0]]))
