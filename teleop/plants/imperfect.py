"""A robot that is not perfect (docs/design.md section 15.1): encoder noise on the measured
configuration, a command latency, a first-order joint velocity response and a calibration
error of its kinematics.

:class:`Imperfections` is the setting, the same for every controller of a run (off by
default); :class:`ImperfectPlant` is the :class:`teleop.loop.Plant` one run's loop uses. The
controller sees the noisy measured ``q``; the true ``q`` moves with the delayed, filtered
command; the loop takes its measures on the true ``q``, with the true kinematics
(:meth:`Imperfections.true_model`) when they differ from the model.
"""

from __future__ import annotations

import collections
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.validation import as_number

from .calibration import miscalibrated_model
from teleop.limits import (
    MAX_CALIBRATION_POSITION_STD_M,
    MAX_CALIBRATION_ROTATION_STD_RAD,
    MAX_ENCODER_NOISE_RAD,
    MAX_LATENCY_PERIODS,
    MAX_LATENCY_S,
    MAX_TIME_CONSTANT_S,
)


@dataclass(frozen=True)
class Imperfections:
    """How the robot differs from the ideal one the controllers assume.

    Attributes
    ----------
    encoder_noise : standard deviation (rad) of the Gaussian noise added to every joint of
        the measured configuration, drawn afresh each control period.
    latency : control periods between a command and the joints receiving it (the joints
        keep still until the first one arrives).
    joint_time_constant : time constant (s) of the first-order response of each joint's
        velocity to the command it receives; 0: the joints follow at once.
    seed : seed of the noise and of the calibration error (a stream of its own,
        :mod:`teleop.plants.calibration`); one run per controller, each from this seed, so
        every controller meets the same noise sequence and the same true robot.
    calibration_position_std : standard deviation (m) of each axis of the translation
        error of every joint placement of the true robot (docs/design.md section 15.1,
        "Calibration error"); the controllers keep the model.
    calibration_rotation_std : standard deviation (rad) of each axis of the rotation
        vector of that error.
    """

    encoder_noise: float = 0.0
    latency: int = 0
    joint_time_constant: float = 0.0
    seed: int = 0
    calibration_position_std: float = 0.0
    calibration_rotation_std: float = 0.0

    def __post_init__(self) -> None:
        """Each field a number in its range, at most the maxima of :mod:`teleop.limits`
        (``ValueError`` naming it)."""
        as_number(self.encoder_noise, "encoder_noise", 0.0, maximum=MAX_ENCODER_NOISE_RAD)
        as_number(self.joint_time_constant, "joint_time_constant", 0.0,
                  maximum=MAX_TIME_CONSTANT_S)
        as_number(self.calibration_position_std, "calibration_position_std", 0.0,
                  maximum=MAX_CALIBRATION_POSITION_STD_M)
        as_number(self.calibration_rotation_std, "calibration_rotation_std", 0.0,
                  maximum=MAX_CALIBRATION_ROTATION_STD_RAD)
        for name, maximum in (("latency", MAX_LATENCY_PERIODS), ("seed", None)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
            if maximum is not None and value > maximum:
                raise ValueError(f"{name} must be <= {maximum} periods, got {value}")

    def check_period(self, dt: float) -> None:
        """Refuse a latency longer than :data:`~teleop.limits.MAX_LATENCY_S` at control
        period ``dt`` (``ValueError``)."""
        if self.latency * dt > MAX_LATENCY_S:
            raise ValueError(f"latency must be <= {MAX_LATENCY_S:g} s, got {self.latency} "
                             f"periods of {dt:g} s = {self.latency * dt:g} s")

    @property
    def exact_joints(self) -> bool:
        """No noise, no latency, no lag: the loop reads and drives the joints exactly."""
        return self.encoder_noise == 0 and self.latency == 0 and self.joint_time_constant == 0

    @property
    def calibrated(self) -> bool:
        """No calibration error: the true kinematics are the model's."""
        return self.calibration_position_std == 0 and self.calibration_rotation_std == 0

    @property
    def perfect(self) -> bool:
        """Exact joints and exact kinematics: the ideal robot the controllers assume."""
        return self.exact_joints and self.calibrated

    def to_dict(self) -> dict[str, float | int]:
        """The ``imperfections`` entry of metrics.json (units in the key names)."""
        return {"encoder_noise_rad": float(self.encoder_noise),
                "latency_periods": int(self.latency),
                "joint_time_constant_s": float(self.joint_time_constant),
                "seed": int(self.seed),
                "calibration_position_std_m": float(self.calibration_position_std),
                "calibration_rotation_std_rad": float(self.calibration_rotation_std)}

    def describe(self) -> str:
        """One line for humans: ``perfect robot`` or what is on."""
        if self.perfect:
            return "perfect robot (no encoder noise, latency, joint lag or calibration error)"
        parts = []
        if self.encoder_noise:
            parts.append(f"encoder noise {self.encoder_noise:g} rad")
        if self.latency:
            parts.append(f"latency {self.latency} period{'s' * (self.latency > 1)}")
        if self.joint_time_constant:
            parts.append(f"joint time constant {self.joint_time_constant:g} s")
        if not self.calibrated:
            parts.append(f"calibration error {1e3 * self.calibration_position_std:g} mm, "
                         f"{1e3 * self.calibration_rotation_std:g} mrad")
        return ", ".join(parts) + f" (seed {self.seed})"

    def plant(self, model: pin.Model, dt: float) -> "ImperfectPlant | None":
        """A fresh plant for one run, or None when the joints are read and driven exactly
        (:attr:`exact_joints`; a calibration error is the loop's, :meth:`true_model`)."""
        self.check_period(dt)
        return None if self.exact_joints else ImperfectPlant(self, model, dt)

    def true_model(self, model: pin.Model) -> pin.Model | None:
        """The true robot's kinematics, ``model`` with this calibration error drawn from
        :attr:`seed` (:func:`~teleop.plants.calibration.miscalibrated_model`), or None
        without one (the true kinematics are ``model``'s)."""
        if self.calibrated:
            return None
        return miscalibrated_model(model, self.calibration_position_std,
                                   self.calibration_rotation_std, self.seed)


class ImperfectPlant:
    """The :class:`teleop.loop.Plant` of :class:`Imperfections` (docs/design.md section 15.1).

    Each period, :meth:`actuate` queues the command, takes the one ``latency`` periods old
    and returns the mean joint velocity over the period of the first-order response to it,
    ``v(t) = u + (v0 - u) exp(-t / tau)``:
    ``mean = u + (v0 - u) tau (1 - exp(-dt / tau)) / dt``, exact for a command held over the
    period. :meth:`sense` adds the encoder noise in the tangent space.
    """

    def __init__(self, imperfections: Imperfections, model: pin.Model, dt: float) -> None:
        if not math.isfinite(dt) or dt <= 0:
            raise ValueError(f"dt must be finite and > 0, got {dt}")
        self.imperfections = imperfections
        self.model = model
        self.dt = float(dt)
        self._rng = np.random.default_rng(imperfections.seed)
        tau = imperfections.joint_time_constant
        self._decay = math.exp(-dt / tau) if tau > 0 else 0.0
        self._mean_gain = tau * (1.0 - self._decay) / dt if tau > 0 else 0.0
        self.reset()

    def reset(self, q: np.ndarray | None = None) -> None:
        """No command in flight, joints still (the noise sequence goes on); the
        configuration ``q`` is the loop's, nothing here keeps one."""
        nv = self.model.nv
        self._queue = collections.deque(np.zeros(nv) for _ in range(self.imperfections.latency))
        self._velocity = np.zeros(nv)

    @property
    def encoder_noise(self) -> float:
        """The encoders' declared noise std (rad), which the loop's state observer reads
        (docs/design.md 5.6)."""
        return self.imperfections.encoder_noise

    def sense(self, q: np.ndarray) -> np.ndarray:
        """``q`` with Gaussian encoder noise on every joint."""
        sigma = self.imperfections.encoder_noise
        if sigma == 0:
            return q
        return pin.integrate(self.model, q, self._rng.normal(0.0, sigma, self.model.nv))

    def actuate(self, qd: np.ndarray, q: np.ndarray | None = None,
                constraints: Sequence[Constraint] = ()) -> np.ndarray:
        """The mean joint velocity over the coming period (delayed, then filtered); the
        configuration and the constraints do not change it."""
        return self.respond(self.delay(qd))

    def advance(self, qd: np.ndarray, q: np.ndarray, constraints: Sequence[Constraint],
                dt: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`actuate`, and the configuration its velocity takes ``q`` to over ``dt``
        (``pin.integrate``)."""
        moved = self.actuate(qd, q, constraints)
        return moved, pin.integrate(self.model, q, moved * dt)

    def delay(self, qd: np.ndarray) -> np.ndarray:
        """The command that reaches the robot this period: ``qd`` of ``latency`` periods
        ago (zero before the first arrives)."""
        self._queue.append(np.array(qd, dtype=float))
        return self._queue.popleft()

    def respond(self, command: np.ndarray) -> np.ndarray:
        """The joints' mean velocity over the period under the command that reached them
        (the first-order response)."""
        start = self._velocity
        self._velocity = command + (start - command) * self._decay
        return command + (start - command) * self._mean_gain

    def close(self) -> None:
        """Nothing to let go: the robot is this process's integrator."""

    def measures(self) -> None:
        """Nothing measured beyond the loop's own figures."""
