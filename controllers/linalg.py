"""The CJM's dense linear algebra: damped least squares and null spaces (paper eq 35).

Rank is decided by the rule of :mod:`controllers.numerics` (``RANK_TOLERANCE`` is that
module's, re-exported here).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .numerics import RANK_TOLERANCE, numerical_rank, rank_cutoff, svd

__all__ = ["RANK_TOLERANCE", "DampedSolution", "DampingPolicy", "damped_least_squares",
           "nullspace"]


@dataclass(frozen=True)
class DampingPolicy:
    """Damped least squares with damping that rises near singularity (paper eq 35).

    ``lambda^2 = damping^2 + max_damping^2 (1 - (sigma_min / threshold)^2)`` while the
    smallest singular value ``sigma_min`` is below ``threshold``, else ``damping^2``
    (Nakamura and Hanafusa's variable damping). ``damping = 0`` and a well-conditioned
    matrix give the exact inverse (paper eq 22). ``sigma_min`` is the smallest value the
    rank keeps: a direction the matrix does not see at all (joints off the EE's path, a
    pre-chain's self-motion under a hole) is dropped, not a singularity to damp
    (docs/design.md section 4.2).
    """

    damping: float = 0.0
    threshold: float = 0.01
    max_damping: float = 0.05

    def __post_init__(self) -> None:
        for name in ("damping", "threshold", "max_damping"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0.0:
                raise ValueError(f"{name} must be finite and >= 0, got {value}")

    def lambda_squared(self, sigma_min: float) -> float:
        lam2 = self.damping**2
        if sigma_min < self.threshold:
            lam2 += self.max_damping**2 * (1.0 - (sigma_min / self.threshold) ** 2)
        return lam2


class DampedSolution(NamedTuple):
    """Result of :func:`damped_least_squares` (a named tuple: cheap to create per step)."""

    x: np.ndarray
    sigma_min: float
    damping: float  # lambda
    row_space: np.ndarray  # right singular vectors with non-zero singular value (rows)
    exact: bool  # no damping, full row rank: J x == r up to rounding

    @property
    def rank(self) -> int:
        return self.row_space.shape[0]


def damped_least_squares(
    matrix: np.ndarray, rhs: np.ndarray, policy: DampingPolicy,
    rank_tolerance: float = RANK_TOLERANCE
) -> DampedSolution:
    """``x = J^T (J J^T + lambda^2 I)^-1 r`` computed through one SVD (paper eq 35).

    Works for square, wide (minimum-norm) and tall (least-squares) ``J``; singular
    values below ``rank_tolerance`` are dropped, so a rank-deficient ``J`` never yields a
    non-finite ``x``. ``rhs`` may be (m,) or (m, k) (k right-hand sides, one SVD).
    """
    u, s, vt = svd(matrix)
    sigma_min = float(s[-1])
    if sigma_min > rank_cutoff(float(s[0]), rank_tolerance):
        lam2 = policy.lambda_squared(sigma_min)
        gains = s / (s * s + lam2)
        row_space = vt
    else:  # rank deficient: drop the null directions instead of dividing by ~0
        rank = numerical_rank(s, rank_tolerance)
        sigma_min = float(s[rank - 1]) if rank else 0.0  # the smallest value kept
        lam2 = policy.lambda_squared(sigma_min)
        gains = np.zeros_like(s)
        gains[:rank] = s[:rank] / (s[:rank] * s[:rank] + lam2)
        row_space = vt[:rank]
    projected = u.T @ rhs
    x = vt.T @ ((gains[:, None] if projected.ndim == 2 else gains) * projected)
    exact = lam2 == 0.0 and row_space.shape[0] == matrix.shape[0]
    return DampedSolution(x=x, sigma_min=sigma_min, damping=lam2**0.5, row_space=row_space,
                          exact=exact)


def nullspace_basis(matrix: np.ndarray, rank_tolerance: float = RANK_TOLERANCE) -> np.ndarray:
    """An orthonormal basis ``N`` of ``null(A)``, shape ``(n, n - rank)``: :func:`nullspace`
    without the pseudo-inverse (whose three NumPy calls its callers would throw away)."""
    m, n = matrix.shape
    if m == 0:
        return np.eye(n)
    _, s, vt = svd(matrix, full_matrices=True)
    return vt[numerical_rank(s, rank_tolerance):].T


def nullspace(matrix: np.ndarray,
              rank_tolerance: float = RANK_TOLERANCE) -> tuple[np.ndarray, np.ndarray, int]:
    """An orthonormal basis ``N`` of ``null(A)``, the pseudo-inverse ``A^+`` and the rank.

    ``N`` has shape ``(n, n - rank)``; ``A^+`` has shape ``(n, m)``.
    """
    m, n = matrix.shape
    if m == 0:
        return np.eye(n), np.zeros((n, 0)), 0
    u, s, vt = svd(matrix, full_matrices=True)
    rank = numerical_rank(s, rank_tolerance)
    pinv = vt[:rank].T @ (u[:, :rank].T / s[:rank, None])
    return vt[rank:].T.copy(), pinv, rank
