"""A step's solver budget: iteration caps per solve, and an optional deadline per step
(docs/design.md section 10.6).

Every solver call of a step is capped in iterations (:data:`ITERATION_CAPS`, always on:
deterministic, so a step's result never depends on the machine's load). A controller on a
robot also gets a wall-clock deadline, by default :data:`DEADLINE_PERIODS` control periods
after the step starts: daqp and OSQP take the time left as their ``time_limit``; proxqp
has none, so the deadline is checked before each of its calls. ``time_budget=None`` keeps
the iteration caps only (the simulated-time experiments: a loaded machine must not turn
their steps into failures). A solve that runs out raises :class:`BudgetExceeded`, a
:class:`SolverError`: the step is ``failed`` with the reason and the command is zero (the
loop holds).
"""

from __future__ import annotations

import time
from typing import Literal

from constraints.validation import as_number

from .base import SolverError

#: The default deadline (``time_budget="periods"``), in control periods: 10 ms at 1 kHz.
DEADLINE_PERIODS = 10

#: Iteration caps per backend, each solve. proxqp's inner iterations are at most
#: ``max_iter * max_iter_in``: the 8.2 s step of issue 18 ran 1000 x 1500 of them on 19 DoF
#: and never converged. docs/design.md section 10.6 gives the worst step times they allow.
ITERATION_CAPS: dict[str, dict[str, int]] = {
    "proxqp": {"max_iter": 100, "max_iter_in": 50},
    "daqp": {"iter_limit": 10000},
    "osqp": {"max_iter": 100000},
}

#: daqp exit flags that mean the budget ran out (iterations, time).
DAQP_OUT_OF_BUDGET = {-4: "iteration limit", -7: "time limit"}

TimeBudget = float | None | Literal["periods"]


class BudgetExceeded(SolverError):
    """A solve ran out of its iteration or time budget."""


class StepBudget:
    """The deadline of one step: :meth:`start` it, then ask :meth:`remaining` (or
    :meth:`time_limit`) before each solve.

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
                          else time.perf_counter() + self.time_budget)

    def remaining(self, solver: str) -> float:
        """Seconds left (> 0; infinite without a deadline), else :class:`BudgetExceeded`
        naming ``solver``."""
        left = self._deadline - time.perf_counter()
        if left <= 0.0:
            raise BudgetExceeded(f"{solver}: the step's time budget "
                                 f"({self.time_budget * 1e3:.3g} ms) is spent")
        return left

    def time_limit(self, solver: str) -> dict[str, float]:
        """``{"time_limit": seconds left}`` for a backend that takes one (empty without a
        deadline); :class:`BudgetExceeded` if none is left."""
        left = self.remaining(solver)
        return {} if self.time_budget is None else {"time_limit": left}

    def exceeded(self, solver: str, what: str) -> BudgetExceeded:
        """The error of a solve of ``solver`` stopped by ``what`` (a limit's name)."""
        budget = ("iteration caps only" if self.time_budget is None
                  else f"step budget {self.time_budget * 1e3:.3g} ms")
        return BudgetExceeded(f"{solver} stopped at its {what} ({budget}): no solution "
                              "within it")
