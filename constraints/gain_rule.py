"""The drift feedback's stability rule (docs/design.md section 3.4), written once."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class GainRule:
    """Drift feedback at gain ``K`` (1/s) and control period ``dt`` (s) is stable when
    ``0 <= K dt < max_gain_period``: 2 for an equality (``e+ = (1 - K dt) e``), 1 for a
    barrier (the point never crosses its plane in discrete time)."""

    max_gain_period: float

    def is_stable(self, gain: float, dt: float) -> bool:
        """Whether gain ``K`` (1/s) is stable at period ``dt`` (s)."""
        return 0.0 <= gain * dt < self.max_gain_period

    def bound(self, dt: float) -> float:
        """The exclusive upper bound of a stable gain (1/s) at period ``dt``."""
        return self.max_gain_period / dt

    def instability(self, type_name: str, gain: float, dt: float) -> str | None:
        """Why ``gain`` is unstable at ``dt`` for a constraint of the class ``type_name``,
        or None when it is stable."""
        if self.is_stable(gain, dt):
            return None
        return (f"{type_name} gain {gain:g} 1/s is unstable at {1.0 / dt:g} Hz "
                f"(K dt = {gain * dt:g}, needs < {self.max_gain_period:g}): lower the gain "
                f"below {self.bound(dt):g} 1/s or raise the rate")
