"""A step's solver budget: iteration caps per solve, and an optional deadline per step
(docs/design.md section 10.6).

Every solver call of a step is capped in iterations (:data:`ITERATION_CAPS`, always on:
deterministic, so a step's result never depends on the machine's load). A controller also
gets a deadline, by default :data:`DEADLINE_PERIODS` control periods of the step's own CPU
time (the calling thread's: what the step computes, not how long the machine made it
wait), checked before each solve; within a solve the caps bound it. ``time_budget=None``
keeps the caps only (the simulated-time experiments). A solve that runs out raises
:class:`BudgetExceeded`, a :class:`SolverError`: the step is ``failed`` with the reason and
the command is zero (the loop holds).
"""

from __future__ import annotations

import time
from typing import Literal

from constraints.validation import as_number

from ..base import SolverError

#: The default deadline (``time_budget="periods"``), in control periods of CPU time: 10 ms
#: at 1 kHz.
DEADLINE_PERIODS = 10

#: Iteration caps per backend, each solve. proxqp's inner iterations are at most
#: ``max_iter * max_iter_in``, which uncapped let one step run for seconds without
#: converging. docs/design.md section 10.6 gives the worst step times they allow.
ITERATION_CAPS: dict[str, dict[str, int]] = {
    "proxqp": {"max_iter": 100, "max_iter_in": 50},
    "daqp": {"iter_limit": 10000},
    "osqp": {"max_iter": 100000},
}

#: daqp exit flags that mean the budget ran out.
DAQP_OUT_OF_BUDGET = {-4: "iteration limit"}

TimeBudget = float | None | Literal["periods"]


class BudgetExceeded(SolverError):
    """A solve ran out of its iteration or time budget."""


class StepBudget:
    """The deadline of one step: :meth:`start` it, then ask :meth:`remaining` before each
    solve.

    ``time_budget``: seconds, ``"periods"`` (:data:`DEADLINE_PERIODS` times ``dt``) or
    None (no deadline: the iteration caps alone bound the step).
    """

    def __init__(self, time_budget: TimeBudget, dt: float) -> None:
        if time_budget == "periods":
            time_budget = DEADLINE_PERIODS * dt
        self.time_budget = (None if time_budget is None
                            else as_number(time_budget, "time_budget", positive=True))
        self._deadline = float("inf")

    def start(self) -> None:
        self._deadline = (float("inf") if self.time_budget is None
                          else time.thread_time() + self.time_budget)

    def remaining(self, solver: str) -> float:
        """CPU seconds left (> 0; infinite without a deadline), else
        :class:`BudgetExceeded` naming ``solver``."""
        left = self._deadline - time.thread_time()
        if left <= 0.0:
            raise BudgetExceeded(f"{solver}: the step's time budget "
                                 f"({self.time_budget * 1e3:.3g} ms of CPU) is spent")
        return left

    def exceeded(self, solver: str, what: str) -> BudgetExceeded:
        """The error of a solve of ``solver`` stopped by ``what`` (a limit's name)."""
        budget = ("iteration caps only" if self.time_budget is None
                  else f"step budget {self.time_budget * 1e3:.3g} ms of CPU")
        return BudgetExceeded(f"{solver} stopped at its {what} ({budget}): no solution "
                              "within it")
