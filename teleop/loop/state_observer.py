"""The joint-state observer: what the loop believes the configuration is (docs/design.md 5.6).

A robot's encoders are noisy; a loop that feeds them raw to the controller turns the noise
into the constraints' drift correction ``-K e`` (3.4), which with ``K = 100 1/s`` makes
1 mrad of noise a demand of tens of mm/s at the port changing every period. The observer
predicts each period with the command the loop sent and corrects with the encoders, per
joint, in the tangent space (a mobile base's heading too)::

    q^-   = integrate(q^, qd_prev dt)                  predict: the command of the last period
    q^    = integrate(q^-, L difference(q^-, q_meas))  correct: gain L in (0, 1]

``L`` is the steady-state Kalman gain of the per-joint model ``q_k = q_k-1 + qd dt + w``,
``z_k = q_k + v`` with ``w ~ N(0, (sigma_v dt)^2)`` (the drives' velocity tracking error,
``sigma_v`` rad/s) and ``v ~ N(0, sigma_n^2)`` (the encoders' noise)::

    Q = (sigma_v dt)^2,  R = sigma_n^2,  P^- = (Q + sqrt(Q^2 + 4 Q R)) / 2,  L = P^- / (P^- + R)

Without noise (``sigma_n = 0``) ``L = 1``: the estimate is the measurement itself, the same
object, and a noise-free run is the run without an observer bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from constraints.validation import as_number

#: the drives' velocity tracking error assumed by default (rad/s, 1 sigma; docs/design.md 5.6)
DEFAULT_VELOCITY_NOISE = 0.01


def kalman_gain(encoder_noise: float, velocity_noise: float, dt: float) -> float:
    """The steady-state Kalman gain ``L`` of the module's per-joint model: encoder noise
    ``sigma_n`` (rad), velocity tracking error ``sigma_v`` (rad/s), period ``dt`` (s).
    1 when there is no encoder noise or the velocity is not known at all."""
    process = (velocity_noise * dt) ** 2
    measurement = encoder_noise ** 2
    if measurement == 0.0 or math.isinf(process):
        return 1.0
    if process == 0.0:
        raise ValueError("velocity_noise must be > 0 when the encoders are noisy "
                         "(a gain of 0 would never read them)")
    prior = 0.5 * (process + math.sqrt(process * process + 4.0 * process * measurement))
    return prior / (prior + measurement)


def estimate_variance(gain: float, encoder_noise: float) -> float:
    """The estimate's steady-state error variance under encoder noise alone (the command
    exact): ``e_k = (1 - L) e_k-1 + L v_k`` gives ``L sigma_n^2 / (2 - L)``."""
    return gain * encoder_noise ** 2 / (2.0 - gain)


@dataclass(frozen=True)
class StateObserverConfig:
    """The observer's settings (docs/design.md 5.6).

    Attributes
    ----------
    enabled : False: the loop takes the encoders raw.
    gain : the correction gain ``L`` in (0, 1]; None: the steady-state Kalman gain of
        ``encoder_noise`` and ``velocity_noise`` (:func:`kalman_gain`).
    encoder_noise : the encoders' noise std (rad); None: what the plant declares
        (its ``encoder_noise``), 0 for a plant that declares none.
    velocity_noise : the drives' velocity tracking error std (rad/s).
    """

    enabled: bool = True
    gain: float | None = None
    encoder_noise: float | None = None
    velocity_noise: float = DEFAULT_VELOCITY_NOISE

    def __post_init__(self) -> None:
        """Each field in its range (``ValueError`` naming it)."""
        if not isinstance(self.enabled, (bool, np.bool_)):
            raise ValueError(f"enabled must be True or False, got {self.enabled!r}")
        if self.gain is not None:
            object.__setattr__(self, "gain",
                               as_number(self.gain, "gain", positive=True, maximum=1.0))
        if self.encoder_noise is not None:
            object.__setattr__(self, "encoder_noise",
                               as_number(self.encoder_noise, "encoder_noise", 0.0))
        object.__setattr__(self, "velocity_noise",
                           as_number(self.velocity_noise, "velocity_noise", positive=True))

    def observer(self, model: pin.Model, declared_noise: float, dt: float) -> "StateObserver":
        """The observer this config gives for ``model`` at period ``dt`` with a plant that
        declares ``declared_noise`` (rad); disabled: one of gain 1 (the encoders raw)."""
        if not self.enabled:
            return StateObserver(model, dt, gain=1.0)
        noise = declared_noise if self.encoder_noise is None else self.encoder_noise
        return StateObserver(model, dt, noise, self.velocity_noise, self.gain)

    def describe(self, gain: float) -> str:
        """In words, with the steady-state gain in use."""
        if not self.enabled:
            return "state observer off (encoders raw)"
        if gain == 1.0:
            return "state observer: encoders raw (no encoder noise declared)"
        return f"state observer gain {gain:.3g}"


class StateObserver:
    """The per-joint predict/correct observer of the module's docstring, one per loop.

    With ``gain`` None the correction gain is the Kalman filter's own, time-varying from
    the first measurement (its variance ``sigma_n^2`` the prior) towards :attr:`gain`::

        P^-_k = P_k-1 + Q,   L_k = P^-_k / (P^-_k + R),   P_k = (1 - L_k) P^-_k

    so the first periods average the encoders (``L`` = 1/2, 1/3, ...) instead of taking
    the first reading's noise for the next ``1 / L`` periods; a given ``gain`` is kept
    from the start.
    """

    def __init__(self, model: pin.Model, dt: float, encoder_noise: float = 0.0,
                 velocity_noise: float = DEFAULT_VELOCITY_NOISE,
                 gain: float | None = None) -> None:
        self.model = model
        self.dt = as_number(dt, "dt", positive=True)
        self._measurement = as_number(encoder_noise, "encoder_noise", 0.0) ** 2
        self._process = (as_number(velocity_noise, "velocity_noise", positive=True)
                         * self.dt) ** 2
        #: the steady-state gain (a given gain, else the Kalman filter's limit)
        self.gain = (kalman_gain(encoder_noise, velocity_noise, self.dt) if gain is None
                     else as_number(gain, "gain", positive=True, maximum=1.0))
        self._fixed = gain is not None
        self._estimate: np.ndarray | None = None
        self._variance = self._measurement

    def reset(self) -> None:
        """Forget the estimate: the next measurement is taken as it is."""
        self._estimate = None

    def _next_gain(self) -> float:
        """This period's gain: the fixed one, or the Kalman filter's step."""
        if self._fixed:
            return self.gain
        prior = self._variance + self._process
        gain = prior / (prior + self._measurement)
        self._variance = (1.0 - gain) * prior
        return gain

    def estimate(self, measured: np.ndarray, command: np.ndarray) -> np.ndarray:
        """The configuration the loop takes this period, from the encoders' ``measured``
        and the command ``command`` sent the period before (rad/s). ``measured`` itself
        when the gain is 1 and at the first period; a non-finite measurement is passed on
        (the loop refuses it) and restarts the observer."""
        if self.gain == 1.0:
            return measured
        if not math.isfinite(sum(measured.tolist())):
            self._estimate = None
            return measured
        if self._estimate is None:
            self._estimate, self._variance = measured, self._measurement
            return measured
        model = self.model
        predicted = pin.integrate(model, self._estimate, command * self.dt)
        innovation = pin.difference(model, predicted, measured)
        self._estimate = pin.integrate(model, predicted, self._next_gain() * innovation)
        return self._estimate
