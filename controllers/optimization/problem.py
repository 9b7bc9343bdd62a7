"""The quadratic program the optimisers hand to a backend, and the backend's answer."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..numerics import TASK_ACCURACY, TOLERANCE_RANGE


class QuadraticProgram(NamedTuple):
    """``min 1/2 x'Hx + g'x  s.t.  A x = b,  l <= C x <= u,  lower <= x <= upper``.

    Absent parts are None; an infinite bound is given as
    ``+-``:data:`~controllers.numerics.INFINITE_BOUND`. ``curvature`` is the smallest
    non-zero eigenvalue of ``H`` on the directions the objective sees (it sets the
    tolerances, :data:`~controllers.numerics.TASK_ACCURACY`); ``semidefinite`` says that
    ``H`` is singular on the feasible set, so that a backend needing a positive definite
    Hessian must regularise it without bias (daqp:
    :data:`~controllers.numerics.DAQP_PROXIMAL_WEIGHT`).
    """

    hessian: np.ndarray
    gradient: np.ndarray
    equality_matrix: np.ndarray | None = None
    equality_rhs: np.ndarray | None = None
    rows: np.ndarray | None = None
    rows_lower: np.ndarray | None = None
    rows_upper: np.ndarray | None = None
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    curvature: float = 1.0
    semidefinite: bool = False

    @property
    def shape(self) -> tuple[int, int, int, bool]:
        """``(variables, equalities, rows, boxed)``: what a persistent solver is built for."""
        return (self.gradient.size,
                0 if self.equality_matrix is None else self.equality_matrix.shape[0],
                0 if self.rows is None else self.rows.shape[0],
                self.lower is not None)

    def tolerance(self) -> float:
        """``TASK_ACCURACY * curvature``, clipped to ``TOLERANCE_RANGE``."""
        return min(max(TASK_ACCURACY * self.curvature, TOLERANCE_RANGE[0]), TOLERANCE_RANGE[1])


class QPSolution(NamedTuple):
    """A backend's answer: ``x`` and the multipliers of the box and of the rows ``C``
    (positive at an upper bound, negative at a lower one; None where absent)."""

    x: np.ndarray
    box_multipliers: np.ndarray | None
    row_multipliers: np.ndarray | None
