"""The supervisor: the loop watches the robot, not only the command (docs/design.md 5.2).

Every period, before the command is computed, :meth:`Supervisor.supervise` measures each
constraint's error at the configuration the loop senses (what a robot's encoders give,
noise included, with the model's kinematics: a robot knows no other) and, on a plant that
measures it, the largest port force of the period before. From them:

* **the measured status**: a step is ``ok`` only while every measured error is within
  ``tolerance`` and the port force within ``force_tolerance``; else the loop records
  ``constraint_degraded`` with the constraint and the measured value in words, the
  controller's own status kept beside it (``StepRecord.controller_status``);
* **the action**: every EE's commanded twist is scaled by ``s``, the smaller of
  ``ramp(e; error_warn, error_hold)`` and ``ramp(F; force_warn, force_hold)`` with
  ``ramp(x; a, b) = clip((b - x) / (b - a), 0, 1)``: 1 below the warning level, falling
  linearly to 0 at the hold level, where the twist is zero and the target held where the
  EE is (the controller still corrects its rows). ``s`` falls at once and rises back by
  at most ``dt / release_time`` a period.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.validation import as_number

#: the supervisor's actions, from none to the strongest (docs/design.md 5.2)
ACTIONS = ("none", "scaled", "held")


@dataclass(frozen=True)
class SupervisorConfig:
    """The supervisor's thresholds (docs/design.md 5.2). Lengths in m, forces in N.

    Attributes
    ----------
    tolerance : a measured constraint error above it makes the step not ``ok``.
    error_warn, error_hold : the operator's twist is scaled down from 1 at ``error_warn``
        to 0 at ``error_hold``, where the target is held.
    force_tolerance, force_warn, force_hold : the same for the largest port force, where
        the plant measures it (the MuJoCo plant's wall).
    release_time : the scale rises back from 0 to 1 in no less than this (s); it falls at
        once.
    acting : False: the supervisor measures and flags, never scales nor holds.
    """

    tolerance: float = 1e-4
    error_warn: float = 5e-4
    error_hold: float = 2e-3
    force_tolerance: float = 0.5
    force_warn: float = 0.5
    force_hold: float = 2.0
    release_time: float = 0.1
    acting: bool = True

    def __post_init__(self) -> None:
        """Every threshold a finite number > 0, each warning level below its hold level
        (``ValueError`` naming the field)."""
        for name in ("tolerance", "error_warn", "error_hold", "force_tolerance", "force_warn",
                     "force_hold"):
            object.__setattr__(self, name, as_number(getattr(self, name), name, positive=True))
        object.__setattr__(self, "release_time",
                           as_number(self.release_time, "release_time", 0.0))
        for warn, hold in (("error_warn", "error_hold"), ("force_warn", "force_hold")):
            if not getattr(self, warn) < getattr(self, hold):
                raise ValueError(f"{warn} must be below {hold}, got {getattr(self, warn):g} "
                                 f">= {getattr(self, hold):g}")
        if not isinstance(self.acting, (bool, np.bool_)):
            raise ValueError(f"acting must be True or False, got {self.acting!r}")

    def to_dict(self) -> dict:
        """The thresholds as metrics.json records them (units in the keys)."""
        return {"tolerance_m": self.tolerance, "error_warn_m": self.error_warn,
                "error_hold_m": self.error_hold, "force_tolerance_n": self.force_tolerance,
                "force_warn_n": self.force_warn, "force_hold_n": self.force_hold,
                "release_time_s": self.release_time, "acting": bool(self.acting)}

    def describe(self) -> str:
        """One line for the command line's summary."""
        thresholds = (f"error ok <= {1e3 * self.tolerance:g} mm, scaled {1e3 * self.error_warn:g}"
                      f"-{1e3 * self.error_hold:g} mm; port force ok <= "
                      f"{self.force_tolerance:g} N, scaled {self.force_warn:g}-"
                      f"{self.force_hold:g} N")
        return f"supervisor {'on' if self.acting else 'measuring only'} ({thresholds})"


def ramp(value: float, warn: float, hold: float) -> float:
    """1 up to ``warn``, 0 from ``hold``, linear between (NaN: not measured, 1)."""
    if not value > warn:
        return 1.0
    return max(0.0, (hold - value) / (hold - warn))


@dataclass(frozen=True)
class Supervision:
    """What the supervisor measured and did in one period.

    Attributes
    ----------
    error : the largest constraint error measured at the sensed configuration (m).
    port_force : the largest port force the plant measured the period before (N); NaN
        when not measured.
    scale : what every EE's commanded twist was multiplied by.
    action : one of :data:`ACTIONS`.
    breach : why the step is not ``ok`` in words (the measure beyond its tolerance), ``""``
        within tolerance.
    words : what the supervisor did and why, ``""`` when it did nothing.
    """

    error: float
    port_force: float
    scale: float
    action: str
    breach: str
    words: str

    def status_of(self, status: str, message: str) -> tuple[str, str]:
        """The loop's status and message for a step whose controller said ``status`` and
        ``message``: ``constraint_degraded`` (``failed`` kept) beyond tolerance; the
        message says what the supervisor measured beyond tolerance and what it did."""
        if not self.breach:
            return status, (message if not self.words
                             else f"{message}; {self.words}" if message else self.words)
        loop_status = "failed" if status == "failed" else "constraint_degraded"
        words = f"measured: {self.breach}"
        if self.words:
            words += f"; {self.words}"
        if status != "ok":
            words += f"; controller: {status}" + (f", {message}" if message else "")
        return loop_status, words


class Supervisor:
    """Measures the sensed robot every period and scales the operator's twist
    (:class:`SupervisorConfig`; docs/design.md 5.2)."""

    def __init__(self, model: pin.Model, config: SupervisorConfig, dt: float) -> None:
        self.model = model
        self.data = model.createData()
        self.config = config
        self.rise = math.inf if config.release_time == 0.0 else dt / config.release_time
        self.scale = 1.0  # the last period's

    def reset(self) -> None:
        self.scale = 1.0

    def supervise(self, sensed: np.ndarray, constraints: Sequence[Constraint],
                  frames: Sequence[int], names: Sequence[str],
                  port_forces: np.ndarray | None) -> Supervision:
        """Measure at ``sensed`` (each constraint at its frame in ``frames``, named by
        ``names``) and the ``port_forces`` (ports, 3) of the period before (None: not
        measured); the period's :class:`Supervision`."""
        config = self.config
        errors = self._errors(sensed, constraints, frames)
        error = max(errors, default=0.0)
        forces = ([] if port_forces is None
                  else [math.sqrt(float(force @ force)) for force in port_forces])
        force = max(forces, default=math.nan)
        wanted = min(ramp(error, config.error_warn, config.error_hold),
                     ramp(force, config.force_warn, config.force_hold)) if config.acting else 1.0
        self.scale = scale = min(wanted, self.scale + self.rise)
        if error <= config.tolerance and not force > config.force_tolerance and scale == 1.0:
            return Supervision(error, force, 1.0, "none", "", "")  # the common case, no words
        worst = errors.index(error) if errors else -1
        port = forces.index(force) if forces else -1
        error_words = (f"{names[worst]} {1e3 * error:.3f} mm off" if worst >= 0 else "")
        port_name = self._port_name(port, constraints, names)
        force_words = f"port force at {port_name} {force:.3f} N" if port >= 0 else ""
        breaches = []
        if error > config.tolerance:
            breaches.append(f"{error_words} (tolerance {1e3 * config.tolerance:g} mm)")
        if force > config.force_tolerance:
            breaches.append(f"{force_words} (tolerance {config.force_tolerance:g} N)")
        breach = "; ".join(breaches)
        action = "none" if scale == 1.0 else "held" if scale == 0.0 else "scaled"
        words = "" if action == "none" else self._action_words(action, scale, wanted, error,
                                                               error_words, force, force_words)
        return Supervision(error, force, scale, action, breach, words)

    def _errors(self, sensed: np.ndarray, constraints: Sequence[Constraint],
                frames: Sequence[int]) -> list[float]:
        """Each constraint's violation (an equality's error, a barrier's penetration, m)
        at ``sensed`` on the model; ``inf`` where it is not finite."""
        if not constraints:
            return []
        pin.framesForwardKinematics(self.model, self.data, sensed)
        placements = self.data.oMf
        errors = [constraint.violation(placements[frame])
                  for constraint, frame in zip(constraints, frames)]
        # a configuration that is not finite measures nothing: as far off as can be
        return errors if math.isfinite(sum(errors)) else [
            error if math.isfinite(error) else math.inf for error in errors]

    def _port_name(self, port: int, constraints: Sequence[Constraint],
                   names: Sequence[str]) -> str:
        """The name of the ``port``-th constraint with a wall (the plant's order)."""
        walls = [name for name, constraint in zip(names, constraints) if constraint.has_wall]
        return walls[port] if 0 <= port < len(walls) else f"port {port + 1}"

    def _action_words(self, action: str, scale: float, wanted: float, error: float,
                      error_words: str, force: float, force_words: str) -> str:
        """``"supervisor scaled the operator's twist to 40 % (hole 1 (link_6) 1.100 mm
        off; warn 0.5 mm, hold 2 mm)"``: the action and the measure that set it (the
        ``error`` or the ``force``, whichever asks the smaller scale)."""
        if wanted == 1.0:
            return f"supervisor releasing the operator's twist: {100 * scale:.0f} %"
        config = self.config
        by_force = ramp(force, config.force_warn, config.force_hold) < ramp(
            error, config.error_warn, config.error_hold)
        cause = (f"{force_words}; warn {config.force_warn:g} N, hold {config.force_hold:g} N"
                 if by_force else f"{error_words}; warn {1e3 * config.error_warn:g} mm, "
                 f"hold {1e3 * config.error_hold:g} mm")
        releasing = ", releasing" if scale < wanted else ""
        if action == "held":
            return f"supervisor held the target: twist zero ({cause})"
        return f"supervisor scaled the operator's twist to {100 * scale:.0f} % ({cause}{releasing})"
