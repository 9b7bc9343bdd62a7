"""The closed loop's settings (docs/design.md section 5): rate, gains, speed caps, target
smoothing, feed-forward, the supervisor's thresholds and the joint-state observer."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from constraints.validation import as_number
from teleop.limits import MAX_POSE_GAIN, MAX_RATE_HZ, MAX_TIME_CONSTANT_S

from .state_observer import StateObserverConfig
from .supervisor_config import SupervisorConfig


@dataclass(frozen=True)
class LoopConfig:
    """Closed-loop settings.

    Attributes
    ----------
    rate : control rate (Hz); ``dt = 1 / rate``.
    kp : pose-error gain (1/s) of ``V_e = K_p log6(T_e^-1 T*)``.
    max_linear_speed, max_angular_speed : saturation of the commanded twist (m/s, rad/s);
        the twist is scaled uniformly so its direction is kept.
    target_time_constant : first-order smoothing of the operator target (s); 0 = none.
    feed_forward : add the target's own twist to the command.
    supervisor : the measured status's and the supervisor's thresholds (docs/design.md 5.2).
    state_observer : the joint-state observer between the encoders and the controller and
        supervisor (docs/design.md 5.6).
    """

    rate: float = 1000.0
    kp: float = 20.0
    max_linear_speed: float = 0.25
    max_angular_speed: float = 1.5
    target_time_constant: float = 0.0
    feed_forward: bool = True
    supervisor: SupervisorConfig = SupervisorConfig()
    state_observer: StateObserverConfig = StateObserverConfig()

    def __post_init__(self) -> None:
        """Every field a real number in its range (``ValueError`` naming it); the rate,
        kp and the smoothing at most :data:`~teleop.limits.MAX_RATE_HZ`,
        :data:`~teleop.limits.MAX_POSE_GAIN` and :data:`~teleop.limits.MAX_TIME_CONSTANT_S`."""
        checked = {
            "rate": as_number(self.rate, "rate", positive=True, maximum=MAX_RATE_HZ),
            "kp": as_number(self.kp, "kp", positive=True, maximum=MAX_POSE_GAIN),
            "max_linear_speed": as_number(self.max_linear_speed, "max_linear_speed",
                                          positive=True),
            "max_angular_speed": as_number(self.max_angular_speed, "max_angular_speed",
                                           positive=True),
            "target_time_constant": as_number(self.target_time_constant, "target_time_constant",
                                              0.0, maximum=MAX_TIME_CONSTANT_S),
        }
        if not isinstance(self.feed_forward, (bool, np.bool_)):
            raise ValueError(f"feed_forward must be True or False, got {self.feed_forward!r}")
        if not isinstance(self.supervisor, SupervisorConfig):
            raise ValueError(f"supervisor must be a SupervisorConfig, got "
                             f"{type(self.supervisor).__name__}")
        if not isinstance(self.state_observer, StateObserverConfig):
            raise ValueError(f"state_observer must be a StateObserverConfig, got "
                             f"{type(self.state_observer).__name__}")
        for name, value in checked.items():
            object.__setattr__(self, name, value)

    @property
    def dt(self) -> float:
        return 1.0 / self.rate
