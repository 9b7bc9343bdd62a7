"""The CJM's damping near singularities, as rows for an optimiser's task
(docs/design.md sections 4.5 and 10.7).

The general CJM damps the task coordinates ``y`` of ``qd = qd_0 + N y`` (``N = null(A)``
orthonormal, ``qd_0 = A^+ b``): ``y = argmin |J N y - r|^2 + lambda^2 |y|^2`` over the
row space of ``J N`` (paper eq 35), with ``lambda`` from ``sigma_min(J N)``
(:class:`~controllers.linalg.DampingPolicy`), the smallest singular value above the rank
cut-off (:mod:`controllers.numerics`): a structural rank deficiency (the Panda's pre-chain
self-motion, which does not move a hole on its last link, leaves ``J N`` with an exact
zero) is no singularity and does not damp; a kept value that falls below the threshold
does. On the rows' solution set ``qd - qd_0 = N y`` and ``N^T qd_0 = 0``, so that term is
``|D qd|^2`` with::

    D = lambda V_r^T N^T        V_r: right singular vectors of J N with non-zero value

An optimiser that adds ``|D qd|^2`` to ``|J qd - V|^2`` under ``A qd = b`` has the CJM's
damped ``y`` on the row space of ``J N`` and leaves ``null(J N)`` to the posture, as the
CJM does: with no inequality binding both commands are the same.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..linalg import DampingPolicy, nullspace_basis
from ..numerics import numerical_rank, svd


class TaskDamping(NamedTuple):
    """``rows`` (r, nv) such that the damping term is ``|rows qd|^2`` (zero rows when the
    CJM does not damp), the smallest non-zero singular value ``sigma_min`` of ``J N``
    (0 when ``J N`` is zero), the ``lambda`` used, ``N = null(A)`` itself and the rank of
    ``J N`` (that of ``[J N; D N]``: ``D`` adds rows in its row space)."""

    rows: np.ndarray
    sigma_min: float
    damping: float
    null_basis: np.ndarray
    rank: int


def task_damping(constraint_rows: np.ndarray | None, task_jacobian: np.ndarray,
                 policy: DampingPolicy) -> TaskDamping:
    """The CJM's damping rows ``D`` for the task ``task_jacobian`` (its rows of non-zero
    weight, ``W^1/2`` applied) under the equality rows ``constraint_rows`` (None: none)."""
    nv = task_jacobian.shape[1]
    null_basis = (np.eye(nv) if constraint_rows is None
                  else nullspace_basis(constraint_rows))
    if not null_basis.shape[1] or not task_jacobian.shape[0]:
        return TaskDamping(np.zeros((0, nv)), float("nan"), 0.0, null_basis, 0)
    _, values, right_vectors = svd(task_jacobian @ null_basis)
    rank = numerical_rank(values)
    if not rank:
        return TaskDamping(np.zeros((0, nv)), 0.0, 0.0, null_basis, 0)
    sigma_min = float(values[rank - 1])
    damping_squared = policy.lambda_squared(sigma_min)
    if damping_squared == 0.0:
        return TaskDamping(np.zeros((0, nv)), sigma_min, 0.0, null_basis, rank)
    damping = damping_squared ** 0.5
    return TaskDamping(damping * (right_vectors[:rank] @ null_basis.T), sigma_min, damping,
                       null_basis, rank)
