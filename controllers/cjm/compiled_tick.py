"""The closed loop's hot path in C++ around the compiled CJM step (docs/design.md 5.1, 16).

One period of ``teleop.loop.TeleopLoop.advance`` (the target filter, the EE placements,
the pose twists with their feed-forward and speed caps, the step, the integration) in one
call to ``controllers.cjm._step.Tick`` (``_step/tick.hpp``), on the pipeline of the
controller's :class:`~controllers.cjm.compiled.CompiledStep`: the EE placements are the
ones the step's own kinematics computes, so the kinematics run once a period (and the
collision rows, when the pipeline measures them). A constraint that declares no compiled
form has its terms written by Python between two calls (``start``, ``end``), as
``CompiledStep.solve`` does. The loop's Python path stays the reference;
tests/test_compiled_tick.py holds the two equal.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Sequence

import numpy as np
import pinocchio as pin

from . import _step
from ._step import TICK_REFUSED, Tick
from .pose_rows import (PERIOD_PLACEMENT, PERIOD_PREVIOUS, PERIOD_TARGET, PERIOD_TWIST, POSE_ROW,
                        POSE_TRANSLATION, pose_rows, row_pose)

if TYPE_CHECKING:
    from .compiled import CompiledStep

# the layouts of the C++ side (_step/pose_row.hpp) are the ones pose_rows.py describes
if ((_step.POSE_ROW, _step.POSE_TRANSLATION, _step.PERIOD_TARGET, _step.PERIOD_PREVIOUS,
     _step.PERIOD_PLACEMENT, _step.PERIOD_TWIST, _step.PERIOD_ROW)
        != (POSE_ROW, POSE_TRANSLATION, PERIOD_TARGET.start, PERIOD_PREVIOUS.start,
            PERIOD_PLACEMENT.start, PERIOD_TWIST.start, PERIOD_TWIST.stop)):
    raise ImportError("controllers.cjm._step holds poses in other rows: rebuild it (pip install -e .)")

#: What :meth:`CompiledTick.run` gives back: the outcome (``_step.TICK_STEPPED``,
#: ``TICK_REFUSED``: the twist was not finite and no step ran, ``TICK_NOT_FINITE``: the
#: command is not finite), the command (None when refused), the next configuration
#: (None unless the tick integrated it), the period (per EE: :mod:`.pose_rows`), the
#: step's time (us, timed in C++), whether the speed caps scaled a twist, and whether
#: the period had a previous target.
TickResult = tuple[int, "np.ndarray | None", "np.ndarray | None", np.ndarray, float, bool, bool]


class CompiledTick:
    """A loop's hot path on ``controller``'s compiled step, its filter's state kept in C++.

    The settings are ``teleop.loop.LoopConfig``'s; the smoothing runs with
    ``alpha = 1 - exp(-dt / tau)`` as the loop computes it (``tau = 0``: none).
    """

    def __init__(self, controller, dt: float, kp: float, max_linear_speed: float,
                 max_angular_speed: float, target_time_constant: float,
                 feed_forward: bool) -> None:
        self.controller = controller
        self.ee_count = len(controller.ee_frame_ids)
        smoothing = (1.0 if target_time_constant == 0.0
                     else 1.0 - math.exp(-dt / target_time_constant))
        self._settings = dict(ee_count=self.ee_count, dt=dt, kp=kp, max_linear=max_linear_speed,
                              max_angular=max_angular_speed, smoothing=smoothing,
                              feed_forward=bool(feed_forward))
        self._tick: Tick | None = None
        #: the last period's stacked twist after the caps (a view, set by :meth:`ready`)
        self.twist: np.ndarray | None = None
        self._step: CompiledStep | None = None  # the step whose pipeline the tick runs
        self._pipeline = None

    def ready(self) -> bool:
        """Whether this period can run compiled: the controller's step is compiled (its
        collision rows, if any, measured by its pipeline); a rebuilt step's pipeline is
        attached (the filter's state stays)."""
        step = self.controller.step
        if step is self._step and step.pipeline is self._pipeline:  # the last period's
            return step.collision_rows is None or step.tick_ready  # pairs still current?
        pipeline = getattr(step, "pipeline", None)
        if pipeline is None or not step.tick_ready:
            return False
        if pipeline is not self._pipeline:
            if self._tick is None:
                self._tick = Tick(pipeline, **self._settings)
            else:
                self._tick.attach(pipeline)
            self._step, self._pipeline = step, pipeline
            self.twist = self._tick.twist
        return True

    def sense(self, q: np.ndarray) -> list[float] | None:
        """Each constraint's violation at ``q`` (m, ``Constraint.violation`` at the
        step's placements, the controller's order) from the step's own kinematics and
        terms, which :meth:`run` at the same ``q`` then reuses (docs/design.md 5.1, 5.2);
        after :meth:`ready`. None when the step is not one call (Python writes some terms),
        ``q`` is not a finite float64 vector of ``nq``, or a constraint's declared
        parameters are refused (``ValueError``: :meth:`run` refuses them too, and the loop
        takes its controlled stop)."""
        if not self._step.one_call:
            return None
        try:
            violations = self._tick.sense(q)
        except ValueError:
            return None
        return None if violations is None else violations.tolist()

    def run(self, poses: Sequence[pin.SE3], q: np.ndarray, integrate: bool) -> TickResult | None:
        """One period towards ``poses`` (one ``pin.SE3`` per EE, checked by the caller) at
        ``q``, after :meth:`ready`; None when ``q`` is not a finite float64 vector of
        ``nq`` (nothing ran: the loop's Python path takes the period). With
        ``integrate``, the next configuration ``integrate(q, qd dt)`` too. The
        controller's ``report`` and ``info`` are the step's, as after its ``solve``."""
        step, tick = self._step, self._tick
        if step.one_call:
            result = tick.run(poses, q, step.use_posture, integrate)
            paper_form = step.paper_form
        else:
            started = tick.start(poses, q)
            if started is None:
                return None
            if not started:
                return tick.refused()
            paper_form = step.write_terms()
            result = tick.end(step.use_posture, paper_form, integrate)
        if result is not None and result[0] != TICK_REFUSED:
            self.controller.take_report(step.last_report(paper_form))
        return result

    # -- the filter's state, handed over to and from the loop's Python path by its pose
    # -- servo (teleop.loop.pose_servo.PoseServo), the one caller of these two --------

    def history(self) -> tuple[list[pin.SE3] | None, list[pin.SE3] | None]:
        """The filtered targets and the previous period's, as poses (None: none yet)."""
        tick = self._tick
        if tick is None:
            return None, None
        return ([row_pose(row) for row in tick.filtered] if tick.has_filtered else None,
                [row_pose(row) for row in tick.previous] if tick.has_previous else None)

    def set_history(self, filtered: Sequence[pin.SE3] | None,
                    previous: Sequence[pin.SE3] | None) -> None:
        """Take over the filter's state (after :meth:`ready`)."""
        tick = self._tick
        tick.filtered[:] = pose_rows(filtered, self.ee_count)
        tick.previous[:] = pose_rows(previous, self.ee_count)
        tick.set_history(filtered is not None, previous is not None)
