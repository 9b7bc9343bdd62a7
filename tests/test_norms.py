"""The norms and products whose rounding the loop's measures share between one period and
many (constraints/norms.py, teleop/loop/constraint_measures.py): the same bits for one
vector as for a stack, whatever BLAS kernel the CPU selects, and within rounding of
numpy's own."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from hypothesis import given, strategies as st
from hypothesis.extra.numpy import arrays

from constraints.norms import norm, row_norms
from teleop.loop.constraint_measures import relative_rotations

EPS = float(np.finfo(float).eps)
finite = st.floats(-1e3, 1e3, allow_subnormal=False)


@given(vectors=st.integers(1, 4).flatmap(
    lambda k: arrays(float, st.tuples(st.integers(1, 20), st.just(k)), elements=finite)))
def test_one_vector_and_a_stack_round_alike(vectors):
    """Each row's :func:`norm` equals its entry of :func:`row_norms` bit for bit, and
    ``np.linalg.norm`` (BLAS) within the rounding of two sums of ``k`` squares and a
    square root: ``(k + 1) eps`` relative."""
    stacked = row_norms(vectors)
    for vector, length in zip(vectors, stacked):
        assert norm(vector) == length
        assert abs(length - np.linalg.norm(vector)) <= (vectors.shape[1] + 1) * EPS * length


rotation_vectors = arrays(float, st.tuples(st.integers(1, 12), st.just(2), st.just(3)),
                         elements=st.floats(-4.0, 4.0, allow_subnormal=False))


@given(rotation_vectors=rotation_vectors)
def test_relative_rotations_of_one_pair_and_a_stack_round_alike(rotation_vectors):
    """``R^T R*`` of each pair alone equals its entry of the stacked product bit for bit,
    and numpy's ``R.T @ R*`` within the rounding of a 3-term dot of unit rows (6 eps)."""
    rotations = np.array([pin.exp3(pair[0]) for pair in rotation_vectors])
    targets = np.array([pin.exp3(pair[1]) for pair in rotation_vectors])
    stacked = relative_rotations(rotations, targets)
    for rotation, target, product in zip(rotations, targets, stacked):
        np.testing.assert_array_equal(relative_rotations(rotation, target), product)
        assert np.max(np.abs(product - rotation.T @ target)) <= 6 * EPS
