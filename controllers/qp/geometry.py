"""The task stage's geometry: ``null(M)`` and the curvature of ``M^T M`` (docs/design.md 10.2)."""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
from scipy.linalg import lapack

from ..numerics import numerical_rank, svd

#: The Cholesky shortcut of :func:`task_geometry` decides only where ``1 / |H^-1|_F``
#: exceeds this times the largest eigenvalue of ``H = M^T M``: forming ``M^T M`` rounds
#: away what lies below ``sqrt(eps)`` relative in ``M`` (a rank-deficient ``M``, as the
#: Panda's with a hole on its last link, factorises with a pivot at rounding level), so
#: anything nearer singular goes to the SVD of ``M`` itself.
GRAM_CERTIFICATE = 1e-12


class TaskGeometry(NamedTuple):
    """``null(M)``, ``M = [A; W^1/2 J_e / sqrt(s)]``, and a curvature of the task Hessian
    ``M^T M``: its smallest non-zero eigenvalue, or a lower bound on it."""

    null_basis: np.ndarray
    curvature: float


def task_geometry(stacked_rows: np.ndarray, hessian: np.ndarray) -> TaskGeometry:
    """``null(M)`` and the curvature of ``hessian = M^T M`` (``M = stacked_rows``).

    Where ``M`` has at least as many rows as columns (no spare DoF on the built-in robots)
    a Cholesky factorisation usually settles it: ``1 / |H^-1|_F``, a lower bound on the
    smallest eigenvalue, above :data:`GRAM_CERTIFICATE` times the largest proves
    ``null(M)`` empty (the counterpart of the CJM's certified LU bound, docs/design.md
    section 4.3; cheaper than the SVD). Otherwise one SVD of ``M`` gives both, its rank by
    the rule of :mod:`controllers.numerics`.
    """
    rows, columns = stacked_rows.shape
    if rows >= columns:
        factor, info = lapack.dpotrf(hessian, lower=1, clean=1)
        if info == 0:
            inverse, info = lapack.dpotrs(factor, _identity(columns), lower=1)
            bound = 1.0 / math.sqrt(float(np.vdot(inverse, inverse))) if info == 0 else 0.0
            largest = max(1.0, float(np.trace(hessian)))  # >= the largest eigenvalue
            if bound > GRAM_CERTIFICATE * largest:
                return TaskGeometry(np.zeros((columns, 0)), bound)
    _, singular_values, right_vectors = svd(stacked_rows, full_matrices=True)
    rank = numerical_rank(singular_values)
    curvature = float(singular_values[rank - 1]) ** 2 if rank else 1.0
    return TaskGeometry(right_vectors[rank:].T.copy(), curvature)


@functools.lru_cache(maxsize=8)
def _identity(size: int) -> np.ndarray:
    """A read-only ``size x size`` identity (the right-hand side of the inverse bound)."""
    identity = np.eye(size)
    identity.setflags(write=False)
    return identity
