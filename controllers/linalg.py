"""Small dense linear algebra shared by the controllers."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.linalg import lapack


#: Singular values at or below this times ``max(1, sigma_max)`` count as zero.
RANK_TOLERANCE = 1e-10


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
    u, s, vt, info = lapack.dgesdd(matrix, full_matrices=0)  # 3x cheaper than numpy's on 6 x 6
    if info != 0:
        raise np.linalg.LinAlgError(f"SVD did not converge (LAPACK dgesdd info {info})")
    sigma_max, sigma_min = float(s[0]), float(s[-1])
    tolerance = rank_tolerance * max(1.0, sigma_max)
    if sigma_min > tolerance:
        lam2 = policy.lambda_squared(sigma_min)
        gains = s / (s * s + lam2)
        row_space = vt
    else:  # rank deficient: drop the null directions instead of dividing by ~0
        keep = s > tolerance
        rank = int(np.count_nonzero(keep))
        sigma_min = float(s[rank - 1]) if rank else 0.0  # the smallest value kept
        lam2 = policy.lambda_squared(sigma_min)
        gains = np.where(keep, s / (s * s + lam2 + ~keep), 0.0)
        row_space = vt[keep]
    projected = u.T @ rhs
    x = vt.T @ ((gains[:, None] if projected.ndim == 2 else gains) * projected)
    exact = lam2 == 0.0 and row_space.shape[0] == matrix.shape[0]
    return DampedSolution(x=x, sigma_min=sigma_min, damping=lam2**0.5, row_space=row_space,
                          exact=exact)


def nullspace(matrix: np.ndarray,
              rank_tolerance: float = RANK_TOLERANCE) -> tuple[np.ndarray, np.ndarray, int]:
    """An orthonormal basis ``N`` of ``null(A)``, the pseudo-inverse ``A^+`` and the rank.

    ``N`` has shape ``(n, n - rank)``; ``A^+`` has shape ``(n, m)``.
    """
    m, n = matrix.shape
    if m == 0:
        return np.eye(n), np.zeros((n, 0)), 0
    # LAPACK's divide-and-conquer SVD, as numpy.linalg.svd, without its Python layer
    u, s, vt, info = lapack.dgesdd(matrix, full_matrices=1)
    if info != 0:
        raise np.linalg.LinAlgError(f"SVD did not converge (LAPACK dgesdd info {info})")
    values = s.tolist()
    tolerance = rank_tolerance * max(1.0, values[0]) if values else 0.0
    rank = sum(1 for value in values if value > tolerance)
    pinv = vt[:rank].T @ (u[:, :rank].T / s[:rank, None])
    return vt[rank:].T.copy(), pinv, rank
