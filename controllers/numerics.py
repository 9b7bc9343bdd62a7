"""Numerical rules and solver settings shared by the controllers (docs/design.md 4.2, 10.2).

* **The rank rule.** One SVD (LAPACK's divide-and-conquer ``dgesdd``, without NumPy's
  Python layer) and one cut-off: a singular value at or below
  ``RANK_TOLERANCE * max(1, sigma_max)`` counts as zero. The CJM's damped least squares and
  null spaces (:mod:`controllers.linalg`), the QP's task geometry, the CJM's damping rows
  and the least-residual stage all decide rank by it.
* **The optimisers' tolerances.** What the QP controller and the mink peer ask of proxqp,
  daqp and OSQP for their normalised task stage and the least-residual stage (section 10.2),
  and what stands for an infinite bound.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import lapack

#: Singular values at or below this times ``max(1, sigma_max)`` count as zero.
RANK_TOLERANCE = 1e-10

#: What stands for an infinite bound in the backends' constraints.
INFINITE_BOUND = 1e20

#: Tolerances per backend. The objectives are divided by the task's scale ``s``
#: (``QPController`` docstring), so their Hessians are of order one on every robot; the
#: primal residuals are in m/s (the constraint rows) and rad/s (the box). proxqp's
#: ``eps_abs`` and daqp's ``eta_prox`` are tightened per step to the curvature (see
#: :data:`TASK_ACCURACY`). OSQP (first order, ADMM) is asked for 1e-7 and polished, with 20
#: refinement steps of its polishing (default 3; docs/design.md 10.2 gives what they buy).
#: ``raise_error=False`` keeps OSQP's failures a "not found" status (as mink's settings
#: do). Residuals are reported, not hidden. Iteration caps and the time limit are the step
#: budget's (:mod:`controllers.optimization.budget`).
SOLVER_SETTINGS: dict[str, dict] = {
    "proxqp": {"eps_abs": 1e-10, "eps_rel": 0.0},
    "daqp": {"primal_tol": 1e-10},
    "osqp": {"eps_abs": 1e-7, "eps_rel": 0.0, "polishing": True, "polish_refine_iter": 20,
             "raise_error": False},
}

#: Accuracy (rad/s) asked of the task stage along its weakest direction. A stationarity
#: residual ``r`` leaves ``qd`` off by ``r / lambda`` along a direction of curvature
#: ``lambda``, so proxqp gets ``eps_abs = TASK_ACCURACY * lambda_min`` and daqp's
#: proximal iterations ``eta_prox = TASK_ACCURACY * lambda_min`` (a step ``dx`` of
#: them leaves about ``dx / lambda_min``), each clipped to :data:`TOLERANCE_RANGE`.
#: ``lambda_min`` is the smallest non-zero eigenvalue of the normalised task Hessian.
TASK_ACCURACY = 1e-8

#: Tightest and loosest tolerance the curvature may set. The tightest is what double
#: precision still resolves (proxqp's dual residual stalls just below it on large chains
#: with binding limits); the loosest holds each constraint row to 1e-11 m/s under proxqp,
#: whose ``eps_abs`` bounds the primal residual too (docs/design.md 10.2).
TOLERANCE_RANGE = (1e-12, 1e-11)

#: proxqp's proximal parameter ``rho`` relative to ``lambda_min`` (at most proxqp's
#: default, 1e-6): its default against a small curvature makes the augmented Lagrangian
#: crawl to its iteration cap (docs/design.md 10.2).
PROXQP_RHO = 1e-4

#: proxqp's ``rho`` relative to ``lambda_min`` for a second solve of a stage that ran to its
#: caps with :data:`PROXQP_RHO`: where collision rows and trocar rows meet the box in a
#: sliver, the task stage ran to its caps in a third of the collision fuzz's steps and
#: converges at this one. Not the first choice: on the least-residual stage of a lock
#: against a collision pair it stops 1e-5 m/s from the optimum (docs/design.md 18.7).
PROXQP_CAPPED_RHO = 1e-8

#: How many times its outer iteration cap a last proxqp solve of a stage still at its caps
#: after :data:`PROXQP_CAPPED_RHO` gets, on a fresh object (its preconditioner computed
#: for that problem, not kept from the first problem of its shape), to the same
#: tolerances: the collision fuzz's failed steps 0.88 % -> 0.18 % (docs/design.md 18.7).
PROXQP_FALLBACK_ITERATIONS = 10

#: proxqp's ``rho`` for the certified flat solve, relative to the stage's tolerance
#: (:meth:`QuadraticProgram.tolerance`): the first solve of a semidefinite stage, the solve
#: after :data:`PROXQP_CAPPED_RHO` of another still at its caps. The stuck one's optimum lies
#: far along directions the Hessian does not see, where the proximal term is the only
#: curvature, and a tolerance-sized one lets them travel there within a few iterations (the
#: collision fuzz's stuck task stage: 17-20 iterations, against over 100,000 at the
#: others). proxqp's "solved" at so small a ``rho`` is taken only with its KKT residual
#: within the tolerance (:mod:`controllers.optimization.kkt`; docs/design.md 18.7).
PROXQP_FLAT_RHO = 1.0

#: Settings of OSQP's second and third solves of a stage that ran to its project cap, each
#: answer taken only with its KKT residual within ``eps_abs``
#: (:mod:`controllers.optimization.kkt`): a fixed ADMM ``rho``, where the adaptive one
#: stalled on the collision fuzz's flat task stages (5 stuck states, still at the cap after
#: 400,000 iterations; 1e-2 finishes 4 of them, 0.1 the fifth; at 1e-3 OSQP said "solved"
#: of one with a KKT residual of 0.11, its polishing failed; docs/design.md 18.7).
OSQP_CAPPED_SETTINGS: tuple[dict, ...] = ({"adaptive_rho": False, "rho": 1e-2},
                                          {"adaptive_rho": False, "rho": 0.1})

#: proxqp's threshold for certifying primal infeasibility (its ``eps_primal_inf``, a
#: field of the persistent objects' settings, which ``proxqp.dense.solve`` through
#: qpsolvers does not take). With the small ``rho`` of a redundant robot
#: (:data:`PROXQP_RHO`) its default 1e-4 certified feasible task stages infeasible;
#: conflicting constraints are still certified at 1e-8.
PROXQP_PRIMAL_INFEASIBILITY = 1e-8

#: daqp settings for a semidefinite task stage (a redundant robot: the task leaves
#: ``null([A; J_e])`` flat). daqp needs a positive definite Hessian, so it solves such a
#: problem by proximal-point iterations, ``min f(x) + eps_prox/2 |x - x_k|^2`` until
#: ``|x_(k+1) - x_k| <= eta_prox``: exact at the fixed point, so the task is not biased.
#: ``eps_prox`` is small against the normalised task curvatures, which then converge in
#: few iterations (docs/design.md 10.2).
DAQP_PROXIMAL_WEIGHT = 1e-8

#: daqp's ``zero_tol`` in a proximal stage, relative to its ``eta_prox``: at daqp's default
#: (1e-11, above the ``eta_prox`` of most stages) the proximal iterations of a stage whose
#: collision rows and trocar rows meet the box in a sliver ran to the iteration cap (297 of
#: 40,000 steps of the collision fuzz); below ``eta_prox`` they converge in tens of
#: iterations to the optimum (docs/design.md 18.7).
DAQP_ZERO_FRACTION = 1e-3

#: The tightest ``eta_prox`` the curvature may set for daqp: tighter moves ``qd`` nearer
#: the CJM's at the price of many more outer iterations (docs/design.md 10.2).
DAQP_PROXIMAL_FLOOR = 1e-13


def svd(matrix: np.ndarray, full_matrices: bool = False
        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(U, s, V^T)`` of ``matrix`` by LAPACK's ``dgesdd``; ``s`` in decreasing order."""
    left, values, right, info = lapack.dgesdd(matrix, full_matrices=int(full_matrices))
    if info != 0:
        raise np.linalg.LinAlgError(f"SVD did not converge (LAPACK dgesdd info {info})")
    return left, values, right


def rank_cutoff(largest: float, rank_tolerance: float = RANK_TOLERANCE) -> float:
    """The value at or below which a singular value counts as zero, given the largest."""
    return rank_tolerance * max(1.0, largest)


def numerical_rank(values: np.ndarray, rank_tolerance: float = RANK_TOLERANCE) -> int:
    """How many of the singular values ``values`` (decreasing, as :func:`svd` gives them)
    exceed :func:`rank_cutoff`."""
    listed = values.tolist()
    if not listed:
        return 0
    cutoff = rank_cutoff(listed[0], rank_tolerance)
    return sum(1 for value in listed if value > cutoff)
