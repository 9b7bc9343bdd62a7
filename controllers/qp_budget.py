"""A step's solver budget: iterations per solve and one deadline per step (docs/design.md
section 10.6).

Every solver call of a step gets an iteration cap and the time left until the step's
deadline: daqp and OSQP take it as their ``time_limit``; proxqp has no time limit, so its
outer and inner iterations are capped and the deadline is checked before each call. A
solve that runs out raises :class:`BudgetExceeded`, a :class:`SolverError`: the step is
``failed`` with the reason and the command is zero (the loop holds).
"""

from __future__ import annotations

import time

from constraints.validation import as_number

from .base import SolverError

#: Wall-clock time a step's solves may take together (s): ten periods at 1 kHz. The
#: bound is wall-clock because daqp's and OSQP's ``time_limit`` are.
DEFAULT_TIME_BUDGET = 10e-3

#: Iteration caps per backend. proxqp's total inner iterations are at most
#: ``max_iter * max_iter_in``: the 8.2 s step of the issue-18 repro ran 1000 x 1500 of
#: them (5 us each on 19 DoF) and never converged; daqp's and OSQP's caps only back up
#: their ``time_limit``.
ITERATION_CAPS: dict[str, dict[str, int]] = {
    "proxqp": {"max_iter": 100, "max_iter_in": 50},
    "daqp": {"iter_limit": 10000},
    "osqp": {"max_iter": 100000},
}

#: daqp exit flags that mean the budget ran out (iterations, time).
DAQP_OUT_OF_BUDGET = {-4: "iteration limit", -7: "time limit"}


class BudgetExceeded(SolverError):
    """A solve ran out of its iteration or time budget."""


class StepBudget:
    """The deadline of one step: :meth:`start` it, then ask :meth:`remaining` before each
    solve."""

    def __init__(self, time_budget: float = DEFAULT_TIME_BUDGET) -> None:
        self.time_budget = as_number(time_budget, "time_budget", positive=True)
        self._deadline = float("inf")

    def start(self) -> None:
        self._deadline = time.perf_counter() + self.time_budget

    def remaining(self, solver: str) -> float:
        """Seconds left (> 0), else :class:`BudgetExceeded` naming ``solver``."""
        left = self._deadline - time.perf_counter()
        if left <= 0.0:
            raise BudgetExceeded(f"{solver}: the step's time budget "
                                 f"({self.time_budget * 1e3:.3g} ms) is spent")
        return left

    def exceeded(self, solver: str, what: str) -> BudgetExceeded:
        """The error of a solve of ``solver`` stopped by ``what`` (a limit's name)."""
        return BudgetExceeded(f"{solver} stopped at its {what} (step budget "
                              f"{self.time_budget * 1e3:.3g} ms): no solution within it")
