"""The supervisor's thresholds (docs/design.md 5.2), on their own: the supervisor
(:mod:`teleop.loop.supervisor`) and its words (:mod:`teleop.loop.supervision_words`) both
read them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from constraints.validation import as_number


@dataclass(frozen=True)
class SupervisorConfig:
    """The supervisor's thresholds (docs/design.md 5.2). Lengths in m, forces in N.

    Attributes
    ----------
    tolerance : a measured constraint error above it makes the step not ``ok``.
    error_warn, error_hold : the operator's motion is scaled down from 1 at
        ``error_warn`` to 0 at ``error_hold``, where the target is held.
    force_tolerance, force_warn, force_hold : the same for the largest port force, where
        the plant measures it (the MuJoCo plant's wall).
    fall_time : the scale falls from 1 to 0 in no less than this (s): the target
        decelerates from the operator's speed over it, never at once.
    release_time : the scale rises back from 0 to 1 in no less than this (s).
    acting : False: the supervisor measures and flags, never scales nor holds.
    """

    tolerance: float = 1e-4
    error_warn: float = 5e-4
    error_hold: float = 2e-3
    force_tolerance: float = 0.5
    force_warn: float = 0.5
    force_hold: float = 2.0
    fall_time: float = 0.2
    release_time: float = 0.3
    acting: bool = True

    def __post_init__(self) -> None:
        """Every threshold a finite number > 0, each warning level below its hold level
        (``ValueError`` naming the field)."""
        for name in ("tolerance", "error_warn", "error_hold", "force_tolerance", "force_warn",
                     "force_hold"):
            object.__setattr__(self, name, as_number(getattr(self, name), name, positive=True))
        for name in ("fall_time", "release_time"):
            object.__setattr__(self, name, as_number(getattr(self, name), name, 0.0))
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
                "fall_time_s": self.fall_time, "release_time_s": self.release_time,
                "acting": bool(self.acting)}

    def describe(self) -> str:
        """One line for the command line's summary."""
        thresholds = (f"error ok <= {1e3 * self.tolerance:g} mm, scaled {1e3 * self.error_warn:g}"
                      f"-{1e3 * self.error_hold:g} mm; port force ok <= "
                      f"{self.force_tolerance:g} N, scaled {self.force_warn:g}-"
                      f"{self.force_hold:g} N; the scale down in {self.fall_time:g} s, up in "
                      f"{self.release_time:g} s")
        return f"supervisor {'on' if self.acting else 'measuring only'} ({thresholds})"
