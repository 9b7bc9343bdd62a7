"""The closed loop's hot path timed (``teleop bench``'s loop section, docs/design.md 5.1).

A scenario (default ``paper-hole``, 10 s at 1 kHz) driven through
:meth:`teleop.loop.TeleopLoop.advance` alone, the measures left out, once with the
compiled tick and once on the loop's Python path; beside them the controller's step alone
(``solve`` from Python at the same configurations and twists), so that the tick's cost
beyond the step reads against the issue's targets: at most 0.5x the step, and a 10 s run
in at most 0.15 s of loop time where the hole step takes 4.5 us (scaled by the step's
median here: absolute times differ 3x between machines of one class). Then ``teleop
compare``'s period, :meth:`teleop.loop.TeleopLoop.tick` (the hot path and the measures of
docs/design.md section 7), against the compiled tick of the same periods (issue 37: at
most 3x), its measures taken after the run as compare takes them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from controllers.cjm import CJMController
from teleop.controller_specs import ROBOT, make_controller
from teleop.loop import LoopConfig, TeleopLoop

from .compare import MEASURED_TOGETHER
from .scenarios import load_scenario

#: the loop time target of a 10 s run (s) on a machine whose hole step is REFERENCE_STEP_US
LOOP_TIME_TARGET_S = 0.15
REFERENCE_STEP_US = 4.5
#: the tick beyond the step, at most this times the step's median
BEYOND_STEP_TARGET = 0.5
#: a scenario whose commands the acceleration box binds most of the time (docs/design.md 9.1)
ACCELERATION_SCENARIO = "fast-lateral"
#: the compiled step (and tick) with acceleration limits, at most this times without (issue 32)
ACCELERATION_COST_TARGET = 1.5
#: runs of the step's timing with and without the limits, interleaved
ACCELERATION_STEP_REPEATS = 5
#: ``teleop compare``'s period (the tick and its measures), at most this times the tick
MEASURED_PERIOD_TARGET = 3.0


@dataclass(frozen=True)
class LoopTiming:
    """One run's ``advance`` times (us) and their sum (s), the compiled tick or not."""

    scenario: str
    compiled_tick: bool
    ticks: int
    loop_time_s: float
    tick_median_us: float
    tick_p99_us: float


def scenario_loop(scenario: str, compiled_tick: bool, duration: float | None,
                  acceleration_limits: bool = False) -> tuple[TeleopLoop, list]:
    """A fresh loop with the CJM on ``scenario`` (the robot's acceleration limits kept
    when ``acceleration_limits``) and its targets over ``duration`` s (default the
    scenario's own) at 1 kHz, drawn first as a device's would arrive."""
    plan = load_scenario(scenario)
    config = LoopConfig()
    steps = int(round((plan.duration if duration is None else duration) / config.dt))
    controller = make_controller("cjm", plan.robot, plan.make_constraints(), dt=config.dt,
                                 acceleration_limit=ROBOT if acceleration_limits else None)
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=config,
                      compiled_tick=compiled_tick)
    return loop, [plan.target((i + 1) * config.dt) for i in range(steps)]


def time_loop(scenario: str, compiled_tick: bool, duration: float | None = None,
              acceleration_limits: bool = False) -> LoopTiming:
    """``scenario`` through ``advance`` alone, nothing else between the periods."""
    loop, targets = scenario_loop(scenario, compiled_tick, duration, acceleration_limits)
    ticks = np.array([loop.advance(target).tick_time_us for target in targets])
    return LoopTiming(scenario, compiled_tick, len(targets), float(ticks.sum()) * 1e-6,
                      float(np.median(ticks)), float(np.percentile(ticks, 99)))


def time_step(scenario: str, duration: float | None = None) -> float:
    """The median (us) of the CJM's ``solve`` from Python alone at the configurations and
    stacked twists of the scenario's periods (a run through the loop first, then a fresh
    controller with the scenario's constraints timed at each)."""
    loop, targets = scenario_loop(scenario, True, duration)
    periods = []
    for target in targets:
        q = loop.q.copy()
        periods.append((q, np.concatenate(loop.advance(target).twists)))
    plan = load_scenario(scenario)
    solver = make_controller("cjm", plan.robot, plan.make_constraints(), dt=loop.config.dt)
    clock = time.perf_counter_ns
    times = np.empty(len(periods))
    for i, (q, twist) in enumerate(periods):
        start = clock()
        solver.solve(q, twist)
        times[i] = (clock() - start) * 1e-3
    return float(np.median(times))


def run_loop_bench(scenario: str = "paper-hole",
                   duration: float | None = None) -> tuple[list[LoopTiming], float]:
    """The compiled tick's and the Python path's runs, then the step's median (us)."""
    return ([time_loop(scenario, True, duration), time_loop(scenario, False, duration)],
            time_step(scenario, duration))


def format_loop_table(timings: list[LoopTiming], step_us: float) -> str:
    """The runs, each tick's median beyond the step over the step, and the loop time
    against its target scaled by the step here."""
    scale = step_us / REFERENCE_STEP_US
    lines = [f"the loop: {timings[0].scenario}, {timings[0].ticks} periods at 1 kHz through "
             f"advance (no measures); the step alone (solve from Python) {step_us:.1f} us",
             f"{'tick':<14}{'median us':>10}{'p99 us':>9}{'beyond step':>13}{'/ step':>8}"
             f"{'loop time s':>13}{'target s':>10}"]
    for timing in timings:
        beyond = timing.tick_median_us - step_us
        run_seconds = timing.ticks * LoopConfig().dt  # the target is for a 10 s run
        target = LOOP_TIME_TARGET_S * scale * run_seconds / 10.0
        missed = [timing.compiled_tick and beyond / step_us > BEYOND_STEP_TARGET,
                  timing.compiled_tick and timing.loop_time_s > target]
        lines.append(f"{'compiled' if timing.compiled_tick else 'python':<14}"
                     f"{timing.tick_median_us:>10.1f}{timing.tick_p99_us:>9.1f}{beyond:>13.1f}"
                     f"{beyond / step_us:>7.2f}{'*' if missed[0] else ' '}"
                     f"{timing.loop_time_s:>12.3f}{'*' if missed[1] else ' '}{target:>9.3f}")
    lines.append(f"targets (the compiled tick, * = missed): beyond the step at most "
                 f"{BEYOND_STEP_TARGET}x the step; the loop time at most {LOOP_TIME_TARGET_S} s "
                 f"per 10 s where the step is {REFERENCE_STEP_US} us ({scale:.2f}x that here)")
    return "\n".join(lines)


def run_acceleration_bench(duration: float | None = None) -> tuple[LoopTiming, LoopTiming]:
    """The compiled tick on :data:`ACCELERATION_SCENARIO` without, then with, the robot's
    acceleration limits (their saturation around the previous command, docs/design.md 9.1)."""
    return (time_loop(ACCELERATION_SCENARIO, True, duration),
            time_loop(ACCELERATION_SCENARIO, True, duration, acceleration_limits=True))


def format_acceleration_line(without: LoopTiming, limited: LoopTiming) -> str:
    """The ticks' medians and p99s with and without the limits, against the target."""
    ratio = limited.tick_median_us / without.tick_median_us
    return (f"acceleration limits: {without.scenario}, the compiled tick's median "
            f"{limited.tick_median_us:.1f} us (p99 {limited.tick_p99_us:.1f}) with them, "
            f"{without.tick_median_us:.1f} us (p99 {without.tick_p99_us:.1f}) without: "
            f"{ratio:.2f}x{'*' if ratio > ACCELERATION_COST_TARGET else ''} "
            f"(target at most {ACCELERATION_COST_TARGET}x)")


@dataclass(frozen=True)
class AccelerationStepCost:
    """The compiled CJM step alone (``CompiledStep.time_steps``: the C++ step in a C++
    loop, no Python between the steps) at one scenario's periods, without and with the
    robot's acceleration limits: each the median over the runs of a run's median (us)."""

    scenario: str
    steps: int
    without_us: float
    limited_us: float
    repeats: int = ACCELERATION_STEP_REPEATS

    @property
    def ratio(self) -> float:
        """The step with the limits over the step without: issue 32's figure."""
        return self.limited_us / self.without_us


def scenario_periods(scenario: str, duration: float | None,
                     acceleration_limits: bool) -> tuple[np.ndarray, np.ndarray]:
    """The configurations (steps x nq) and stacked twists of ``scenario``'s periods,
    from a run through the loop with the compiled tick."""
    loop, targets = scenario_loop(scenario, True, duration, acceleration_limits)
    configurations, twists = [], []
    for target in targets:
        configurations.append(loop.q.copy())
        twists.append(np.concatenate(loop.advance(target).twists))
    return np.array(configurations), np.array(twists)


def time_acceleration_steps(duration: float | None = None,
                            repeats: int = ACCELERATION_STEP_REPEATS
                            ) -> AccelerationStepCost | None:
    """The compiled step on :data:`ACCELERATION_SCENARIO`'s periods without, then with,
    the robot's acceleration limits, ``repeats`` runs each, interleaved; each run a fresh
    controller from rest, so the limits' box follows the same previous commands as in the
    loop. None when the step is not the compiled one-call step (nothing to time in C++)."""
    plan = load_scenario(ACCELERATION_SCENARIO)
    dt = LoopConfig().dt
    periods = {limits: scenario_periods(ACCELERATION_SCENARIO, duration, limits)
               for limits in (False, True)}
    medians: dict[bool, list[float]] = {False: [], True: []}
    for _ in range(repeats):
        for limits, (configurations, twists) in periods.items():
            controller = make_controller("cjm", plan.robot, plan.make_constraints(), dt=dt,
                                         acceleration_limit=ROBOT if limits else None)
            step = controller.step if isinstance(controller, CJMController) else None
            time_steps = getattr(step, "time_steps", None)  # the compiled step's only
            nanoseconds = None if time_steps is None else time_steps(configurations, twists)
            if nanoseconds is None:
                return None
            medians[limits].append(float(np.median(nanoseconds)) * 1e-3)
    return AccelerationStepCost(ACCELERATION_SCENARIO, len(periods[True][0]),
                                float(np.median(medians[False])), float(np.median(medians[True])),
                                repeats)


def format_acceleration_step_line(cost: AccelerationStepCost | None) -> str:
    """The step's medians with and without the limits and their ratio, against the target."""
    if cost is None:
        return ("acceleration limits: the compiled step alone not timed (the CJM's step is "
                "not the compiled one-call step here)")
    return (f"acceleration limits: {cost.scenario}, the compiled step alone (time_steps, "
            f"{cost.steps} periods, median of {cost.repeats} runs' medians) "
            f"{cost.limited_us:.2f} us with them, {cost.without_us:.2f} us without: "
            f"{cost.ratio:.2f}x{'*' if cost.ratio > ACCELERATION_COST_TARGET else ''} "
            f"(issue 32's target at most {ACCELERATION_COST_TARGET}x)")


@dataclass(frozen=True)
class MeasuredPeriod:
    """``teleop compare``'s periods: :meth:`TeleopLoop.tick_measured_later` (the compiled
    tick and what the measures read, kept) timed around the call, the compiled tick alone
    in the same periods, and a period's measures taken after the run, as compare takes
    them (:meth:`TeleopLoop.measure_all_later`) (us)."""

    scenario: str
    ticks: int
    period_median_us: float
    period_p99_us: float
    tick_median_us: float
    measures_after_us: float

    @property
    def ratio(self) -> float:
        """The hot path's median over the tick's."""
        return self.period_median_us / self.tick_median_us

    @property
    def total_ratio(self) -> float:
        """The period with its measures (the hot path's median plus the measures' after
        the run) over the tick's: what the target bounds, whenever the measures run."""
        return (self.period_median_us + self.measures_after_us) / self.tick_median_us


def time_measured_period(scenario: str = "paper-hole",
                         duration: float | None = None) -> MeasuredPeriod:
    """``scenario`` as ``teleop compare`` runs it: each period through
    :meth:`TeleopLoop.tick_measured_later` timed around the call, then the measures after
    the run, :data:`~teleop.experiments.compare.MEASURED_TOGETHER` periods at a time
    (:meth:`TeleopLoop.measure_all_later`), each batch's CPU time (``thread_time``: a
    batch takes milliseconds, long enough to be preempted on a loaded machine, where a
    period's median is not) per period, their median."""
    loop, targets = scenario_loop(scenario, True, duration)
    clock = time.perf_counter_ns
    periods, ticks = np.empty(len(targets)), np.empty(len(targets))
    kept = []
    for i, target in enumerate(targets):
        start = clock()
        period = loop.tick_measured_later(target)
        periods[i] = (clock() - start) * 1e-3
        ticks[i] = period.step.tick_time_us
        kept.append(period)
    measures = []
    for first in range(0, len(kept), MEASURED_TOGETHER):
        batch = kept[first:first + MEASURED_TOGETHER]
        start = time.thread_time_ns()
        loop.measure_all_later(batch)
        measures.append((time.thread_time_ns() - start) * 1e-3 / len(batch))
    return MeasuredPeriod(scenario, len(targets), float(np.median(periods)),
                          float(np.percentile(periods, 99)), float(np.median(ticks)),
                          float(np.median(measures)))


def format_measured_period_line(period: MeasuredPeriod) -> str:
    """compare's period with its measures against the tick's median and the target (the
    measures counted wherever they run), then the hot path alone (the tick and what its
    measures read) and the measures after the run."""
    missed = "*" if period.total_ratio > MEASURED_PERIOD_TARGET else ""
    total = period.period_median_us + period.measures_after_us
    return (f"compare's period: {period.scenario}, with its measures {total:.1f} us, the "
            f"compiled tick {period.tick_median_us:.1f} us: {period.total_ratio:.2f}x{missed} "
            f"(target at most {MEASURED_PERIOD_TARGET}x); the hot path "
            f"{period.period_median_us:.1f} us median (p99 {period.period_p99_us:.1f}, "
            f"{period.ratio:.2f}x), a period's measures after the run "
            f"{period.measures_after_us:.1f} us (CPU time, {MEASURED_TOGETHER} measured together)")
