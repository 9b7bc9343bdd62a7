"""proxqp as persistent ``proxsuite`` dense QPs (docs/design.md section 10.2)."""

from __future__ import annotations

from typing import Any

from ..base import SolverError
from ..numerics import (PROXQP_CAPPED_RHO, PROXQP_FALLBACK_ITERATIONS, PROXQP_FLAT_RHO,
                        PROXQP_PRIMAL_INFEASIBILITY, PROXQP_RHO)
from .budget import StepBudget
from .kkt import kkt_residual
from .problem import QPSolution, QuadraticProgram

#: proxqp settings that are arguments of ``init`` rather than fields of ``settings``.
INIT_ARGUMENTS = frozenset({"rho", "mu_eq", "mu_in", "compute_preconditioner",
                            "manual_minimal_H_eigenvalue"})


class ProxQPSolver:
    """Persistent ``proxsuite.proxqp.dense.QP`` objects: ``init`` once per problem shape,
    ``update`` + ``solve`` after. Used by the QP controller and, for its proxqp solves, by
    the mink peer.

    ``tuned`` names the settings this class may choose per solve, the user having set
    none of them: ``"eps_abs"`` (:meth:`QuadraticProgram.tolerance`) and ``"rho"``
    (``PROXQP_RHO`` times it), from each problem's curvature, and ``"max_iter"`` (the last
    solve's larger cap below; a cap the user set is never exceeded).

    The task stage and the posture stage have different shapes, so each gets its own
    object (keyed by :attr:`QuadraticProgram.shape`). The joint bounds go in proxsuite's
    box constraints, the other inequality rows in ``C``. All objects are dropped after a
    failed solve, so that a bad state never carries over. ``update`` keeps the
    preconditioner of ``init``: recomputing it every step cost more than it saved, and
    the stopping test is on the unscaled residuals, so the tolerances hold either way.
    It restarts the penalty parameters ``mu_eq``, ``mu_in`` from their initial values,
    as ``init`` does: carried over from the previous step, they made proxqp stop at a
    wrong point reported as solved, at a spurious infeasibility or at the iteration cap
    on the generated chains with binding limits (docs/design.md 10.2).
    proxqp takes a semidefinite Hessian as it is: its proximal term acts only while it
    iterates, and directions the objective does not see feel no force.

    ``initial_guess`` (a ``proxsuite.proxqp.InitialGuess`` name, in ``solver_settings``)
    defaults to ``EQUALITY_CONSTRAINED_INITIAL_GUESS``, which is what a fresh proxqp solve
    uses: on the built-in robots it needs no more iterations than
    ``WARM_START_WITH_PREVIOUS_RESULT`` on a smooth closed loop, and warm starting from the
    previous result now and then stopped at a spurious ``PROXQP_PRIMAL_INFEASIBLE`` on
    independent configurations. With a warm start chosen, a step that does not reach
    ``PROXQP_SOLVED`` is solved again from the equality-constrained guess before it is
    reported as a failure. A solve that runs to its caps with ``rho`` set from the
    curvature is solved once more with ``PROXQP_CAPPED_RHO`` in its place; one still at
    its caps is solved a last time the same two ways on a fresh object (its own
    preconditioner) with ``PROXQP_FALLBACK_ITERATIONS`` times the outer cap, while the
    step's deadline leaves time and the cap is not the user's: an answer from there
    meets the same tolerances as any. A stage still at its caps then is one whose optimum
    lies far along directions its Hessian does not see, pushed there by a force of the
    order of the tolerance (the collision fuzz's stuck task stage: three wrist joints
    driven to their velocity limits by box multipliers of at most 3e-8, through a held
    collision row), where the proximal term
    is the only curvature and each outer iteration moves them by about ``force / rho``.
    Such a stage is solved on a fresh object with ``rho`` at the stage's own tolerance
    (:data:`PROXQP_FLAT_RHO`), its answer taken only if its KKT residual
    (:func:`kkt_residual`, complementarity included, which proxqp's "solved" does not
    check) is within that tolerance (docs/design.md 18.7). A semidefinite stage
    (:attr:`QuadraticProgram.semidefinite`: directions its Hessian does not see) takes
    that certified flat solve **first**, and the solves above only if it is not
    certified: the first capped solve alone of the collision fuzz's stuck stage costs
    about 9.2-9.9 ms of CPU (100 outer, 1,828-1,877 inner iterations), which spent the
    step's default 10 ms budget before the flat solve (0.3-0.5 ms) could run. Other
    stages take the flat solve where they are still at their caps after
    :data:`PROXQP_CAPPED_RHO`, before the larger cap's. Both only when the user set
    neither ``rho`` nor ``max_iter``.
    """

    def __init__(self, settings: dict, tuned: frozenset[str]) -> None:
        import proxsuite  # noqa: PLC0415 - only when proxqp is the backend

        self._proxqp = proxsuite.proxqp
        self.init_arguments = {k: v for k, v in settings.items() if k in INIT_ARGUMENTS}
        self.settings = {"eps_primal_inf": PROXQP_PRIMAL_INFEASIBILITY,
                         **{k: v for k, v in settings.items() if k not in INIT_ARGUMENTS}}
        guess = self.settings.pop("initial_guess", "EQUALITY_CONSTRAINED_INITIAL_GUESS")
        if isinstance(guess, str):
            if guess not in proxsuite.proxqp.InitialGuess.__members__:
                raise ValueError(f"unknown proxqp initial_guess {guess!r}; one of "
                                 f"{list(proxsuite.proxqp.InitialGuess.__members__)}")
            guess = proxsuite.proxqp.InitialGuess.__members__[guess]
        self.initial_guess = guess
        self.fallback_guess = proxsuite.proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
        self.solved = proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
        self.capped = proxsuite.proxqp.QPSolverOutput.PROXQP_MAX_ITER_REACHED
        self.tuned = tuned  # of "eps_abs", "rho", "max_iter": chosen here, per solve
        self.solvers: dict[tuple[int, int, int, bool], Any] = {}  # proxsuite's dense QPs

    @staticmethod
    def accepts(settings: dict) -> bool:
        """Whether every key is a proxqp setting this class can apply (else: qpsolvers)."""
        import proxsuite  # noqa: PLC0415

        fields = set(dir(proxsuite.proxqp.dense.QP(1, 0, 0).settings))
        return all(k in fields or k in INIT_ARGUMENTS for k in settings)

    def reset(self) -> None:
        self.solvers.clear()

    def _fresh(self, problem: QuadraticProgram, arguments: tuple, proximal: dict) -> Any:
        """A new dense QP of ``problem``'s shape with the settings, initialised on it."""
        qp = self._proxqp.dense.QP(*problem.shape[:3], box_constraints=problem.shape[3])
        for key, value in self.settings.items():
            setattr(qp.settings, key, value)
        qp.settings.initial_guess = self.initial_guess
        if "eps_abs" in self.tuned:
            qp.settings.eps_abs = problem.tolerance()
        qp.init(*arguments, **self.init_arguments, **proximal)
        return qp

    def _run(self, qp: Any, problem: QuadraticProgram) -> Any:
        """Solve ``qp`` as loaded: from the equality-constrained guess again if a warm start
        failed, with :data:`PROXQP_CAPPED_RHO` again if it ran to its caps; its status."""
        qp.solve()
        status = qp.results.info.status
        if status != self.solved and self.initial_guess != self.fallback_guess:
            qp.settings.initial_guess = self.fallback_guess
            qp.solve()
            qp.settings.initial_guess = self.initial_guess
            status = qp.results.info.status
        if status == self.capped and "rho" in self.tuned:
            qp.update(rho=min(1e-6, PROXQP_CAPPED_RHO * problem.curvature), **self.penalties(qp))
            qp.solve()
            status = qp.results.info.status
        return status

    def penalties(self, qp: Any) -> dict[str, float]:
        """The initial ``mu_eq``, ``mu_in`` of ``qp`` (the user's, else proxqp's)."""
        return {"mu_eq": self.init_arguments.get("mu_eq", qp.settings.default_mu_eq),
                "mu_in": self.init_arguments.get("mu_in", qp.settings.default_mu_in)}

    def _flat(self, problem: QuadraticProgram, arguments: tuple, qp: Any,
              status: Any) -> tuple[Any, Any]:
        """The last solve with ``rho`` at :data:`PROXQP_FLAT_RHO` times the stage's
        tolerance, on a fresh object with
        :data:`PROXQP_FALLBACK_ITERATIONS` times the outer cap; its object and status if
        its answer is certified within its ``eps_abs``, else ``qp`` and ``status``."""
        flat = self._fresh(problem, arguments, {"rho": PROXQP_FLAT_RHO * problem.tolerance()})
        flat.settings.max_iter *= PROXQP_FALLBACK_ITERATIONS
        flat.solve()
        if flat.results.info.status != self.solved:
            return qp, status
        n_rows, boxed = problem.shape[2:]
        results = flat.results
        residual = kkt_residual(problem, results.x, results.y, results.z[:n_rows],
                                results.z[n_rows:] if boxed else None)
        return (flat, self.solved) if residual <= flat.settings.eps_abs else (qp, status)

    def _persistent(self, problem: QuadraticProgram, arguments: tuple, proximal: dict) -> Any:
        """The persistent object of ``problem``'s shape, loaded with it."""
        qp = self.solvers.get(problem.shape)
        if qp is None:
            qp = self._fresh(problem, arguments, proximal)
            self.solvers[problem.shape] = qp
        else:
            if "eps_abs" in self.tuned:
                qp.settings.eps_abs = problem.tolerance()
            qp.update(*arguments, **proximal, **self.penalties(qp))
        return qp

    def solve(self, problem: QuadraticProgram, budget: StepBudget) -> QPSolution:
        budget.remaining("proxqp")
        _, _, n_rows, boxed = problem.shape
        arguments = (problem.hessian, problem.gradient, problem.equality_matrix,
                     problem.equality_rhs, problem.rows, problem.rows_lower, problem.rows_upper,
                     *((problem.lower, problem.upper) if boxed else ()))
        proximal = ({"rho": min(1e-6, PROXQP_RHO * problem.curvature)}
                    if "rho" in self.tuned else {})
        # a semidefinite stage: the certified flat solve first (0.2-0.3 ms on the fuzz's
        # stuck stage, whose first capped solve alone spent ~9.5 of the 10 ms budget)
        flat_first = problem.semidefinite and {"rho", "max_iter"} <= self.tuned
        status = None
        if flat_first:
            qp, status = self._flat(problem, arguments, None, None)
        if status != self.solved:
            if flat_first:
                budget.remaining("proxqp")
            qp = self._persistent(problem, arguments, proximal)
            status = self._run(qp, problem)
        if status == self.capped and "max_iter" in self.tuned:
            # the flat solve (if not tried first) before the larger cap: about 20
            # iterations where it applies (0.3-0.5 ms), where the larger cap costs ~28 ms
            if "rho" in self.tuned and not flat_first:
                budget.remaining("proxqp")
                qp, status = self._flat(problem, arguments, qp, status)
            if status == self.capped:
                budget.remaining("proxqp")
                last = self._fresh(problem, arguments, proximal)
                last.settings.max_iter *= PROXQP_FALLBACK_ITERATIONS
                if self._run(last, problem) == self.solved:
                    qp, status = last, self.solved
        if status != self.solved:
            self.reset()
            if status == self.capped:
                raise budget.exceeded("proxqp", f"iteration limit ({qp.settings.max_iter} "
                                      f"x {qp.settings.max_iter_in} iterations)")
            raise SolverError(f"proxqp found no solution ({status.name})")
        multipliers = qp.results.z  # the rows C, then the box
        return QPSolution(qp.results.x.copy(), multipliers[n_rows:].copy() if boxed else None,
                          multipliers[:n_rows].copy() if n_rows else None)

