"""What the mink peer asks of its backends, in mink's units (docs/design.md 10.2, 10.5)."""

from __future__ import annotations

from ..optimization.budget import ITERATION_CAPS

#: Solver settings in the units of *velocity* (rad/s, m/s); they are multiplied by ``dt``
#: before they reach the backend, because mink's QP variable is ``dq = v dt``: a
#: tolerance of 1e-10 on ``v`` is 1e-13 on ``dq`` at 1 kHz. daqp is an active-set solver
#: whose equalities are exact to rounding; proxqp is asked for 1e-11 so that the
#: equality rows hold to 1e-9 m/s or better; OSQP (ADMM, first order) for 1e-7 with
#: polishing, and its residual is reported, not hidden.
VELOCITY_TOLERANCES: dict[str, dict[str, float]] = {
    "proxqp": {"eps_abs": 1e-11},
    "daqp": {"primal_tol": 1e-10},
    "osqp": {"eps_abs": 1e-7},
}

#: Settings passed as they are (no unit). ``eq_reduction=1`` makes daqp eliminate the
#: equality rows before it factorises the Hessian. Without it, mink's Hessian
#: ``J_e^T J_e + damping I`` (rank 6 + damping on 8 joints) has pivots below daqp's
#: ``sing_tol``; daqp then switches to its automatic proximal regularisation and stops
#: away from the solution (docs/design.md 10.2). ``raise_error=False`` keeps OSQP's
#: failures as a "not found" status (and silences its deprecation warning).
FIXED_SETTINGS: dict[str, dict] = {
    "proxqp": {"eps_rel": 0.0},
    "daqp": {"eq_reduction": 1},
    "osqp": {"eps_rel": 0.0, "polishing": True, "max_iter": 20000, "raise_error": False},
}

#: Iteration caps of mink's solves: the QP controller's, but proxqp's. mink's QP
#: (``mink.build_ik``, in ``dq`` units, the posture's curvature ``c^2`` small) is solved
#: by the shared proxsuite objects (``ProxQPSolver``), which take both ``max_iter`` and
#: ``max_iter_in`` (``qpsolvers``' proxqp path takes no inner cap). Fewer outer and more
#: inner iterations than the QP controller's, with a margin over what the recovery from
#: a hole jump needs (tests/test_qp_recovery.py; docs/design.md 10.6 gives the numbers
#: and the worst step they allow).
MINK_ITERATION_CAPS: dict[str, dict[str, int]] = {
    **ITERATION_CAPS, "proxqp": {"max_iter": 50, "max_iter_in": 100}}

#: Cost of the posture task relative to the task's scale (``MinkController.posture_cost``:
#: mink's cost is ``c = posture_cost * sqrt(s)``). The posture bends the twist by about
#: ``c^2 / sigma^2``, and for ``c`` too small mink's solve no longer resolves the posture
#: (``c^2`` in ``dq`` units against tolerances of 1e-13). The choice is measured against
#: the CJM with no limit binding in docs/design.md section 10.
DEFAULT_POSTURE_COST = 1e-5

#: mink's ``damping`` without a posture task: it keeps mink's Hessian ``J_e^T J_e``
#: definite on a redundant robot. A posture task does that itself (``c^2 I``), and a
#: damping then pulls the redundancy towards zero with a weight ``damping / c^2``, off
#: the CJM's posture (docs/design.md 10.5), so it defaults to 0 there.
DEFAULT_DAMPING = 1e-12
