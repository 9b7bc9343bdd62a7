"""The session's settings: the constraints' gain, the CJM's damping, the orientation
weight and the control rate (docs/design.md section 5.3)."""

from __future__ import annotations

import dataclasses
import threading

from constraints import Constraint
from constraints.validation import as_number
from teleop.loop import LoopConfig, TeleopLoop
from teleop.loop.task_modes import AUTO, task_mode

from .limits import MAX_DAMPING, checked_rate


class Settings:
    """The settings of :class:`web.app.TeleopApp` (its state: ``gain``, ``damping``,
    ``orientation_weight``, ``config``)."""

    config: LoopConfig
    gain: float
    damping: float
    orientation_weight: float
    task_mode: str
    entries: dict
    specs: dict[str, str]
    loops: dict[str, TeleopLoop]
    _lock: threading.RLock

    def set_gain(self, gain: float) -> None:
        """Gain K (1/s) of every constraint: the drift feedback of the equalities, the
        approach rate of the one-sided constraints, stable at this rate by
        :meth:`constraints.Constraint.gain_is_stable`. A gain some placed constraint
        cannot take at this rate raises ``ValueError`` naming the gain and changes
        nothing."""
        gain = as_number(gain, "gain")
        with self._lock:
            dt = self.config.dt
            if not Constraint.gain_is_stable(gain, dt):
                raise ValueError(f"gain must be in [0, {Constraint.stable_gain_bound(dt):g}) "
                                 f"1/s at this rate, got {gain:g}")
            previous = self.gain
            try:  # each constraint checks the gain at its controllers' period
                for entry in self.entries.values():
                    entry.constraint.gain = gain
                self.gain = gain
                self._sync_constraints()
            except ValueError:
                self.gain = previous
                for entry in self.entries.values():
                    entry.constraint.gain = previous
                self._sync_constraints()
                raise

    def set_damping(self, damping: float) -> None:
        """Constant DLS damping lambda of the CJM (paper eq 35), in [0, MAX_DAMPING]."""
        damping = as_number(damping, "damping", 0.0, maximum=MAX_DAMPING)
        with self._lock:
            self.damping = damping
            for loop in self.loops.values():
                self._apply_damping(loop.controller)

    def set_orientation_weight(self, weight: float) -> None:
        """Weight in [0, 1] of every EE twist's angular entries against the linear ones
        (every controller's ``twist_weight``): 1 asks for full poses; with two trocars on
        one torso, which leave 11 joint directions for 12 entries, a lower weight lets the
        orientations give way so the tips go where they are dragged. Rebuilds the loops,
        keeps the state."""
        weight = as_number(weight, "orientation weight", 0.0, maximum=1.0)
        self._rebuild(dict(self.specs), orientation_weight=weight)

    def set_task_mode(self, mode: str) -> None:
        """What the operator commands of every EE (docs/design.md section 20): ``pose``,
        ``position_roll`` (position and roll about the tool axis), ``position``, or
        ``auto`` (position and roll on a chain with a port, else the full pose); the
        rows left out go to the controllers' null space. Every loop changes in place; an
        unknown mode raises ``ValueError`` and changes nothing."""
        if mode != AUTO:
            task_mode(mode)  # ValueError naming the modes
        with self._lock:
            self.task_mode = mode
            self._apply_task_modes()

    def set_rate(self, rate: float) -> None:
        """Control rate (Hz), in [MIN_RATE, MAX_RATE]; rebuilds the loops (QP limits depend
        on dt), keeps the state."""
        rate = checked_rate(rate)
        self._rebuild(dict(self.specs), config=dataclasses.replace(self.config, rate=rate))
