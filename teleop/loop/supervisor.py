"""The supervisor: the loop watches the robot, not only the command (docs/design.md 5.2).

Every period, before the command is computed, :meth:`Supervisor.supervise` measures each
constraint's error at the configuration the loop senses (what a robot's encoders give,
noise included, with the model's kinematics: a robot knows no other) and, on a plant that
measures it, the largest port force of the period before. From them:

* **the measured status**: a step is ``ok`` only while every measured error is within
  ``tolerance`` and the port force within ``force_tolerance``; else the loop records
  ``constraint_degraded`` with the constraint and the measured value in words, the
  controller's own status kept beside it (``StepRecord.controller_status``);
* **the action**: the operator's motion is scaled by ``s``, which follows the smaller of
  ``ramp(e; error_warn, error_hold)`` and ``ramp(F; force_warn, force_hold)`` with
  ``ramp(x; a, b) = clip((b - x) / (b - a), 0, 1)`` (1 below the warning level, falling
  linearly to 0 at the hold level) at a bounded rate: down by at most ``dt / fall_time``,
  up by at most ``dt / release_time`` a period. The loop follows the **supervised
  target** (:meth:`Supervisor.follow`), which moves by ``s`` times the operator target's
  motion of each period, as the input mapping moves a target (docs/design.md 19.1)::

      p_s <- p_s + s (p_k - p_k-1)
      R_s <- exp3(s log3(R_k R_k-1^T)) R_s

  so at ``s = 0`` the target is held where it was and the pose servo brings the EE to it
  at its own pace; the offset from the operator's target that builds while ``s < 1`` is
  kept afterwards, as a clutch's.
"""

from __future__ import annotations

import math
from functools import partial
from typing import NamedTuple, Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from controllers.step_message import NO_MESSAGE, StepMessage

from .supervision_words import SupervisionWords
from .supervisor_config import SupervisorConfig

#: the supervisor's actions, from none to the strongest (docs/design.md 5.2)
ACTIONS = ("none", "scaled", "held")


def ramp(value: float, warn: float, hold: float) -> float:
    """1 up to ``warn``, 0 from ``hold``, linear between (NaN: not measured, 1)."""
    if not value > warn:
        return 1.0
    return max(0.0, (hold - value) / (hold - warn))


class Supervision(NamedTuple):
    """What the supervisor measured and did in one period (a named tuple: immutable and
    built in one call, every period), its words written when read
    (:class:`~teleop.loop.supervision_words.SupervisionWords`).

    Attributes
    ----------
    error : the largest constraint error measured at the sensed configuration (m).
    port_force : the largest port force the plant measured the period before (N); NaN
        when not measured.
    scale : what the operator's motion of the period was multiplied by.
    action : one of :data:`ACTIONS`.
    breach_message : why the step is not ``ok`` (the measure beyond its tolerance), read
        as :attr:`breach`.
    words_message : what the supervisor did and why, read as :attr:`words`.
    target_offset : the largest distance between an EE's supervised target and the
        operator's (m): what the scaled motion left behind, kept as a clutch's.
    target_offset_angle : the largest angle between their orientations (rad).
    beyond : a measure is beyond its tolerance (the breach says which).
    acted : the supervisor has something to say (it scales or holds the motion, or keeps
        an offset).
    """

    error: float
    port_force: float
    scale: float
    action: str
    breach_message: StepMessage = NO_MESSAGE
    words_message: StepMessage = NO_MESSAGE
    target_offset: float = 0.0
    target_offset_angle: float = 0.0
    beyond: bool = False
    acted: bool = False

    @property
    def breach(self) -> str:
        """Why the step is not ``ok`` in words, ``""`` within tolerance."""
        return self.breach_message.text

    @property
    def words(self) -> str:
        """What the supervisor did and why, ``""`` when it did nothing."""
        return self.words_message.text

    def status_of(self, status: str, message: StepMessage) -> tuple[str, StepMessage]:
        """The loop's status and message for a step whose controller said ``status`` and
        ``message``: ``constraint_degraded`` (``failed`` kept) beyond tolerance; the
        message says what the supervisor measured beyond tolerance and what it did
        (:meth:`message_of`), worded when read. Within tolerance and without words, the
        controller's own."""
        if not self.beyond:
            return status, (message if not self.acted
                            else StepMessage(partial(self.message_of, status, message)))
        loop_status = "failed" if status == "failed" else "constraint_degraded"
        return loop_status, StepMessage(partial(self.message_of, status, message))

    def message_of(self, status: str, message: StepMessage) -> str:
        """The words of :meth:`status_of`'s message: the controller's message and the
        supervisor's words within tolerance; beyond it, what was measured, what the
        supervisor did and what the controller said (its status unless ``ok``)."""
        text = message.text
        if not self.beyond:
            return f"{text}; {self.words}" if text else self.words
        words = f"measured: {self.breach}"
        if self.acted:
            words += f"; {self.words}"
        if status != "ok":
            words += f"; controller: {status}" + (f", {text}" if text else "")
        return words


class Supervisor:
    """Measures the sensed robot every period and scales the operator's motion into the
    target the loop follows (:class:`SupervisorConfig`; docs/design.md 5.2)."""

    def __init__(self, model: pin.Model, config: SupervisorConfig, dt: float) -> None:
        self.model = model
        self.data = model.createData()
        self.config = config
        self.fall = math.inf if config.fall_time == 0.0 else dt / config.fall_time
        self.rise = math.inf if config.release_time == 0.0 else dt / config.release_time
        self.scale = 1.0  # the last period's
        #: the operator's targets of the period before (copies), None before the first
        self.operator_targets: list[pin.SE3] | None = None
        #: per EE, the supervised target's offset from the operator's: a world translation
        #: ``d`` and a rotation ``R_d`` (``p_s = p + d``, ``R_s = R_d R``); None: none built
        self.offsets: list[tuple[np.ndarray, np.ndarray]] | None = None
        self.target_offset = 0.0  # the largest |d| (m)
        self.target_offset_angle = 0.0  # the largest |log3(R_d)| (rad)
        #: the targets the loop follows; None while they are the operator's own (no offset)
        self.supervised_targets: list[pin.SE3] | None = None

    def reset(self) -> None:
        self.scale = 1.0
        self.operator_targets = None
        self.offsets = None
        self.target_offset = self.target_offset_angle = 0.0
        self.supervised_targets = None

    def hold(self, ee: int, pose: pin.SE3) -> None:
        """The operator's previous target of EE ``ee`` at ``pose`` and its offset gone (a
        watchdog's stop: the operator's target and the loop's are set there)."""
        if self.operator_targets is not None:
            self.operator_targets[ee] = pose.copy()
        if self.offsets is not None:
            self.offsets[ee] = (np.zeros(3), np.eye(3))
            self._measure_offsets()

    def supervise(self, sensed: np.ndarray, operator_targets: Sequence[pin.SE3],
                  constraints: Sequence[Constraint], frames: Sequence[int],
                  names: Sequence[str], port_forces: np.ndarray | None,
                  violations: list[float] | None = None) -> Supervision:
        """Measure at ``sensed`` (each constraint at its frame in ``frames``, named by
        ``names``; ``violations``: their violations there when the caller computed them,
        the compiled tick's) and the ``port_forces`` (ports, 3) of the period before (None:
        not measured), move the supervised targets by the period's share of the operator's
        motion to ``operator_targets`` (:meth:`follow`, read them in
        :attr:`followed_targets`); the period's :class:`Supervision`."""
        config = self.config
        errors = self._errors(sensed, constraints, frames, violations)
        error = max(errors, default=0.0)
        forces = ([] if port_forces is None
                  else [math.sqrt(float(force @ force)) for force in port_forces])
        force = max(forces, default=math.nan)
        error_ramp = ramp(error, config.error_warn, config.error_hold)
        force_ramp = ramp(force, config.force_warn, config.force_hold)
        wanted = min(error_ramp, force_ramp) if config.acting else 1.0
        self.scale = scale = min(max(wanted, self.scale - self.fall), self.scale + self.rise)
        offset, angle = self.follow(operator_targets, scale)
        beyond = error > config.tolerance or force > config.force_tolerance
        if not beyond and scale == 1.0 and self.offsets is None:
            return Supervision(error, force, 1.0, "none")  # the common case, no words
        action = "none" if scale == 1.0 else "held" if scale == 0.0 else "scaled"
        acted = not (action == "none" and self.offsets is None)  # else beyond tolerance only
        words = SupervisionWords(config, action, scale, wanted, force_ramp < error_ramp, error,
                                 errors.index(error) if errors else -1, force,
                                 forces.index(force) if forces else -1, names, constraints,
                                 offset, angle)
        return Supervision(error, force, scale, action,
                           StepMessage(words.breach) if beyond else NO_MESSAGE,
                           StepMessage(words.action_words) if acted else NO_MESSAGE,
                           offset, angle, beyond, acted)

    @property
    def followed_targets(self) -> list[pin.SE3]:
        """The targets the loop follows this period: the supervised ones, or the
        operator's own while no offset was ever built."""
        return self.supervised_targets or self.operator_targets

    def follow(self, operator_targets: Sequence[pin.SE3],
               scale: float) -> tuple[float, float]:
        """Move each supervised target by ``scale`` times the operator target's motion
        since the period before (world frame, docs/design.md 5.2):
        ``p_s += s dp``, ``R_s <- exp3(s log3(R_k R_k-1^T)) R_s``, kept as the offset from
        the operator's target (:meth:`_scale_motion`, which only ``s < 1`` changes); the
        largest offset's distance (m) and angle (rad). Without an offset they are the
        operator's own (copies)."""
        previous = self.operator_targets
        self.operator_targets = [pose.copy() for pose in operator_targets]
        if scale != 1.0 and previous is not None:
            self._scale_motion(previous, operator_targets, scale)
        offsets = self.offsets
        self.supervised_targets = None if offsets is None else [
            pin.SE3(rotation @ pose.rotation, pose.translation + translation)
            for (translation, rotation), pose in zip(offsets, operator_targets)]
        return self.target_offset, self.target_offset_angle

    def _scale_motion(self, previous: Sequence[pin.SE3], operator_targets: Sequence[pin.SE3],
                      scale: float) -> None:
        """Each offset grown by the share of the operator's motion from ``previous`` the
        ``scale`` leaves out: ``d += (s - 1) dp``, ``R_d <- exp3(s log3(turn)) R_d turn^T``
        with ``turn = R_k R_k-1^T``, so that the supervised target moves by ``s dp`` and
        turns by ``exp3(s log3(turn))``. A motion that is not finite (a bad target, which
        the controller refuses, docs/design.md 15.6) leaves the offset as it was."""
        offsets = self.offsets or [(np.zeros(3), np.eye(3)) for _ in operator_targets]
        grown = []
        for (translation, rotation), before, now in zip(offsets, previous, operator_targets):
            motion = now.translation - before.translation
            turn = now.rotation @ before.rotation.T
            if not math.isfinite(float(motion.sum() + turn.sum())):
                grown.append((translation, rotation))
                continue
            grown.append((translation + (scale - 1.0) * motion,
                          pin.exp3(scale * pin.log3(turn)) @ rotation @ turn.T))
        self.offsets = grown
        self._measure_offsets()

    def _measure_offsets(self) -> None:
        """:attr:`target_offset` and :attr:`target_offset_angle` of :attr:`offsets`."""
        offsets = self.offsets or []
        self.target_offset = max((float(np.linalg.norm(d)) for d, _ in offsets), default=0.0)
        self.target_offset_angle = max((float(np.linalg.norm(pin.log3(rotation)))
                                        for _, rotation in offsets), default=0.0)

    def _errors(self, sensed: np.ndarray, constraints: Sequence[Constraint],
                frames: Sequence[int], violations: list[float] | None) -> list[float]:
        """Each constraint's violation (an equality's error, a barrier's penetration, m)
        at ``sensed`` on the model (``violations`` when given); ``inf`` where it is not
        finite."""
        if not constraints:
            return []
        if violations is not None:
            errors = violations
        else:
            pin.framesForwardKinematics(self.model, self.data, sensed)
            placements = self.data.oMf
            errors = [constraint.violation(placements[frame])
                      for constraint, frame in zip(constraints, frames)]
        # a configuration that is not finite measures nothing: as far off as can be
        return errors if math.isfinite(sum(errors)) else [
            error if math.isfinite(error) else math.inf for error in errors]
