"""Euclidean norms whose rounding is the same for one vector as for a stack of them, and
does not depend on the BLAS kernel the CPU selects (docs/design.md section 7): the squares
summed in index order, ``sqrt((x_0^2 + x_1^2) + x_2^2 ...)``, in element-wise numpy
operations, which never fuse a multiply and an add. A dot product or ``np.linalg.norm``
calls BLAS (with AVX-512 OpenBLAS fuses the products), so the same vector's norm could
differ in its last bit between the loop's measures taken period by period and taken over
many periods at once.
"""

from __future__ import annotations

import math

import numpy as np


def norm(vector: np.ndarray) -> float:
    """The Euclidean norm of one short vector, in Python floats."""
    total = 0.0
    for entry in vector.tolist():
        total += entry * entry
    return math.sqrt(total)


def row_norms(vectors: np.ndarray) -> np.ndarray:
    """:func:`norm` of each vector along the last axis of ``vectors`` (..., k): the same
    operations in the same order, bit for bit."""
    total = np.zeros(vectors.shape[:-1])
    for index in range(vectors.shape[-1]):
        entry = vectors[..., index]
        total = total + entry * entry
    return np.sqrt(total)
