"""The supervisor's words for one period, written when read (docs/design.md 5.2).

:meth:`teleop.loop.supervisor.Supervisor.supervise` decides every period from numbers
(the measured error and port force against the thresholds, the scale, the offset); once
it has acted, every period also has something to say (the scale, the measure that set
it, the offset kept as a clutch's). A :class:`SupervisionWords` keeps the figures of one
period, and :class:`~controllers.step_message.StepMessage` objects word them for the
readers that ask (a record's message, the UI's status line), not on the hot path.
"""

from __future__ import annotations

import math
from typing import Sequence

from constraints import Constraint
from teleop.plants.walls import has_wall

from .supervisor_config import SupervisorConfig


class SupervisionWords:
    """One period's supervision in words, from its figures.

    ``config``: the thresholds; ``action``: ``"none"``, ``"scaled"`` or ``"held"``;
    ``scale`` and ``wanted``: the scale applied and the one the measures asked for;
    ``by_force``: the port force asked the smaller scale (else the error); ``error`` (m)
    of constraint ``worst`` (-1: none measured), ``force`` (N) at port ``port`` (-1: none
    measured), named by ``names`` and found among the ``constraints`` with a wall (the
    loop's of the period: replaced, never changed in place, when the constraints
    change); ``offset`` (m) and ``angle`` (rad):
    the supervised target's largest offset from the operator's.
    """

    __slots__ = ("config", "action", "scale", "wanted", "by_force", "error", "worst",
                 "force", "port", "names", "constraints", "offset", "angle")

    def __init__(self, config: SupervisorConfig, action: str, scale: float, wanted: float,
                 by_force: bool, error: float, worst: int, force: float, port: int,
                 names: Sequence[str], constraints: Sequence[Constraint], offset: float,
                 angle: float) -> None:
        self.config, self.action, self.scale, self.wanted = config, action, scale, wanted
        self.by_force, self.error, self.worst = by_force, error, worst
        self.force, self.port, self.names, self.constraints = force, port, names, constraints
        self.offset, self.angle = offset, angle

    def breach(self) -> str:
        """``"hole 1 (link_6) 0.812 mm off (tolerance 0.1 mm)"``: each measure beyond its
        tolerance (the error, the port force), ``"; "`` between them."""
        config = self.config
        breaches = []
        if self.error > config.tolerance:
            breaches.append(f"{self.error_words()} (tolerance {1e3 * config.tolerance:g} mm)")
        if self.force > config.force_tolerance:
            breaches.append(f"{self.force_words()} (tolerance {config.force_tolerance:g} N)")
        return "; ".join(breaches)

    def action_words(self) -> str:
        """``"supervisor scaled the operator's motion to 79 % (hole 1 (link_6) 0.812 mm
        off; warn 0.5 mm, hold 2 mm); target 0.310 mm, 0.00 deg from the operator's"``:
        the action, the measure that set it (the error or the port force, whichever asks
        the smaller scale) and the offset the scaled motion left, which stays when the
        scale is back at 1 (a clutch's)."""
        action, scale, wanted = self.action, self.scale, self.wanted
        offset_words = (f"target {1e3 * self.offset:.3f} mm, {math.degrees(self.angle):.2f} "
                        "deg from the operator's")
        if action == "none":
            return f"supervisor: {offset_words} (kept, as a clutch)"
        if wanted == 1.0:
            return (f"supervisor releasing: the operator's motion scaled to {100 * scale:.3g} %; "
                    f"{offset_words}")
        config = self.config
        cause = (f"{self.force_words()}; warn {config.force_warn:g} N, hold "
                 f"{config.force_hold:g} N" if self.by_force
                 else f"{self.error_words()}; warn {1e3 * config.error_warn:g} mm, "
                 f"hold {1e3 * config.error_hold:g} mm")
        if action == "held":
            return f"supervisor: target held, the operator's motion not followed ({cause}); " \
                   f"{offset_words}"
        direction = "falling" if scale > wanted else "rising" if scale < wanted else ""
        return (f"supervisor scaled the operator's motion to {100 * scale:.3g} % ({cause}"
                f"{', ' + direction if direction else ''}); {offset_words}")

    def error_words(self) -> str:
        """``"hole 1 (link_6) 0.812 mm off"``, ``""`` without a constraint."""
        worst = self.worst
        return f"{self.names[worst]} {1e3 * self.error:.3f} mm off" if worst >= 0 else ""

    def force_words(self) -> str:
        """``"port force at hole 1 (link_6) 1.234 N"``, ``""`` without a port."""
        return f"port force at {self.port_name()} {self.force:.3f} N" if self.port >= 0 else ""

    def port_name(self) -> str:
        """The name of the ``port``-th constraint with a wall (the plant's order)."""
        port = self.port
        walls = [name for name, constraint in zip(self.names, self.constraints)
                 if has_wall(constraint)]
        return walls[port] if 0 <= port < len(walls) else f"port {port + 1}"
