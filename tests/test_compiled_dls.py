"""The compiled step's damped least squares chooses its decomposition by the problem
(``_step/damped.hpp``, docs/design.md section 16) and decides as LAPACK's SVD does.

Hypothesis draws matrices ``U diag(s) V^T`` of every shape up to 20 x 20 (beyond the QR
path's 16) with chosen singular values: well conditioned, near the damping threshold,
far below it, exactly zero, around the rank cut. Against NumPy's LAPACK SVD (and the
Python reference :func:`controllers.linalg.damped_least_squares`), the compiled DLS
gives the same rank (``numpy.linalg.matrix_rank`` with the rank rule's cut), the same
sigma_min (1e-9 relative, the backends' figure), the same damping and exactness, the same
row space (to ``2 p q eps`` times its own condition, ``sigma_max / sigma_min`` of the kept
values), and ``x`` within ``2 p q eps kappa`` of the reference (relative to
``1 + max |x|``; ``kappa`` the condition number with the damping flooring sigma_min, at
least 1, times ``1 + 2 (max_damping / threshold)^2`` below the threshold, where eq 35's
``lambda(sigma_min)`` carries sigma_min's rounding into ``x``).
The QR path is taken exactly where the class's certificate says it may: always for a
well-conditioned undamped matrix of at most 16 columns or rows, never below the
threshold, never with a constant damping.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controllers.cjm import _step
from controllers.linalg import RANK_TOLERANCE, DampingPolicy, damped_least_squares

EPS = np.finfo(float).eps
#: the QR path's largest min(p, q) and condition bound (DampedLeastSquares' constants)
MAX_QR_SIZE = 16
MAX_CONDITION_BOUND = 1e4


def orthonormal(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """``k`` orthonormal columns in R^n (the Q of a Gaussian matrix)."""
    q, _ = np.linalg.qr(rng.normal(size=(n, k)))
    return q


@st.composite
def problems(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, DampingPolicy]:
    """A ``p x q`` matrix with drawn singular values, two right-hand sides, a policy."""
    p = draw(st.integers(1, 20))
    q = draw(st.integers(1, 20))
    t = min(p, q)
    scale = draw(st.sampled_from([1e-3, 1.0, 30.0]))
    kind = draw(st.sampled_from(["well", "near_threshold", "singular", "rank_loss",
                                 "around_cut"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    s = scale * rng.uniform(0.5, 2.0, size=t)
    if kind == "near_threshold":  # the smallest around the damping threshold
        s[-1] = 0.01 * draw(st.sampled_from([0.5, 0.99, 1.01, 1.5, 4.0]))
    elif kind == "singular":  # damped: far below the threshold, above the cut
        s[-1] = draw(st.sampled_from([1e-4, 1e-6, 1e-8]))
    elif kind == "rank_loss":
        s[draw(st.integers(0, t - 1)):] = 0.0
    elif kind == "around_cut":  # a factor 100 either side of the cut, not on it
        cut = RANK_TOLERANCE * max(1.0, float(np.max(s)))
        s[-1] = cut * draw(st.sampled_from([1e-2, 1e2]))
    matrix = orthonormal(rng, p, t) @ np.diag(s) @ orthonormal(rng, q, t).T
    rhs = rng.normal(size=(p, 2)) * draw(st.sampled_from([1e-6, 1.0, 1e3]))
    damping = draw(st.sampled_from([0.0, 0.0, 0.0, 1e-3]))
    return matrix, rhs, s, DampingPolicy(damping=damping)


def assert_figures_are_lapacks(matrix: np.ndarray, figures: tuple, reference) -> None:
    """The compiled DLS's rank, sigma_min, damping, exactness and row space (``figures``,
    the binding's tuple after x) against NumPy's SVD and the Python reference."""
    sigma_min, damping, rank, exact, row_space = figures[:5]
    singular_values = np.linalg.svd(matrix, compute_uv=False)
    cut = RANK_TOLERANCE * max(1.0, float(singular_values[0]))
    assert rank == np.linalg.matrix_rank(matrix, tol=cut) == reference.rank
    assert np.isclose(sigma_min, reference.sigma_min, rtol=1e-9, atol=1e-13 * max(1.0, singular_values[0]))
    assert np.isclose(damping, reference.damping, rtol=1e-9, atol=1e-12)
    assert exact == reference.exact
    p, q = matrix.shape
    kept = singular_values[:rank]
    # the kept subspace is defined to eps sigma_max / sigma_min (its smallest kept value)
    subspace = 2.0 * p * q * EPS * (float(kept[0] / kept[-1]) if rank else 1.0)
    np.testing.assert_allclose(row_space @ row_space.T, reference.row_space.T @ reference.row_space,
                               rtol=0.0, atol=subspace)


def certified(s: np.ndarray) -> bool:
    """Whether the QR's certificate holds for singular values ``s`` whatever the
    matrix's vectors: 1/||R^-1||_F >= sigma_min / sqrt(t) clears the rank cut (taken at
    ||R||_F <= sqrt(t) sigma_max) and ||R||_F ||R^-1||_F <= t kappa stays under the bound,
    with a margin for the rounding of R."""
    t = s.size
    sigma_min, sigma_max = float(np.min(s)), float(np.max(s))
    return (sigma_min / np.sqrt(t) > RANK_TOLERANCE * max(1.0, np.sqrt(t) * sigma_max) * (1.0 + 1e-6)
            and t * sigma_max / sigma_min < MAX_CONDITION_BOUND * (1.0 - 1e-6))


@settings(max_examples=600, deadline=None)
@given(problem=problems())
def test_compiled_dls_decides_and_solves_as_lapack(problem):
    matrix, rhs, _, policy = problem
    x, *figures = _step.damped_least_squares(
        matrix, rhs, policy.damping, policy.threshold, policy.max_damping, RANK_TOLERANCE)
    reference = damped_least_squares(matrix, rhs, policy)
    assert_figures_are_lapacks(matrix, tuple(figures), reference)
    damping, rank = figures[1], figures[2]
    singular_values = np.linalg.svd(matrix, compute_uv=False)
    p, q = matrix.shape
    kept = singular_values[:rank]
    kappa = max(1.0, float(kept[0]) / max(float(kept[-1]), damping)) if rank else 1.0
    if rank and kept[-1] < policy.threshold:  # lambda(sigma_min) moves with sigma_min's rounding
        kappa *= 1.0 + 2.0 * (policy.max_damping / policy.threshold) ** 2
    bound = 2.0 * p * q * EPS * kappa * (1.0 + float(np.max(np.abs(reference.x))))
    assert float(np.max(np.abs(x - reference.x))) <= bound


@settings(max_examples=400, deadline=None)
@given(problem=problems())
def test_the_qr_path_is_taken_where_the_certificate_holds(problem):
    matrix, rhs, s, policy = problem
    by_qr = _step.damped_least_squares(matrix, rhs, policy.damping, policy.threshold,
                                       policy.max_damping, RANK_TOLERANCE)[-1]
    # below the damping threshold too: a solve first takes lambda from the certified
    # sigma_min and solves the damped problem on the QR (DampedLeastSquares::damped_by_qr)
    rank_lost = np.min(s) <= RANK_TOLERANCE * max(1.0, float(np.max(s)))
    if policy.damping > 0.0 or min(matrix.shape) > MAX_QR_SIZE or rank_lost:
        assert not by_qr
    elif certified(s):
        assert by_qr


@settings(max_examples=400, deadline=None)
@given(problem=problems())
def test_the_figures_before_a_solve_need_no_svd_where_the_certificate_holds(problem):
    """sigma_min, lambda, the rank and the row space asked for without a solve (the
    damping rows of the saturation around the previous command, docs/design.md 9.1): LAPACK's
    figures, from the QR's certificate and the certified sigma_min alone wherever the
    certificate holds, below the damping threshold too."""
    matrix, rhs, s, policy = problem
    x, *figures = _step.damped_least_squares(
        matrix, rhs, policy.damping, policy.threshold, policy.max_damping, RANK_TOLERANCE,
        solve=False)
    assert x is None
    assert_figures_are_lapacks(matrix, tuple(figures), damped_least_squares(matrix, rhs, policy))
    by_qr = figures[-1]
    rank_lost = np.min(s) <= RANK_TOLERANCE * max(1.0, float(np.max(s)))
    if policy.damping > 0.0 or min(matrix.shape) > MAX_QR_SIZE or rank_lost:
        assert not by_qr
    elif certified(s):
        assert by_qr


def test_a_dual_robot_sized_task_takes_the_qr_path():
    """The dual robot's ``J_e N``: 12 x 11, well conditioned, least squares."""
    rng = np.random.default_rng(3)
    matrix = orthonormal(rng, 12, 11) @ np.diag(np.linspace(0.2, 1.5, 11)) @ orthonormal(rng, 11, 11).T
    rhs = rng.normal(size=(12, 1))
    x, sigma_min, damping, rank, exact, row_space, by_qr = _step.damped_least_squares(
        matrix, rhs, 0.0, 0.01, 0.05, RANK_TOLERANCE)
    assert by_qr and rank == 11 and damping == 0.0 and not exact
    assert abs(sigma_min - 0.2) <= 1e-13
    np.testing.assert_allclose(x, np.linalg.lstsq(matrix, rhs, rcond=None)[0], rtol=0, atol=1e-13)
