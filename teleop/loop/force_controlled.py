"""A controller whose EE twist passes a tool-frame force law first (docs/design.md section
21.6): the way a loop that follows the operator's targets (:class:`TeleopLoop`, the page)
runs the hybrid law of :mod:`.hybrid_force_motion` without a loop of its own.

The loop computes each EE's body twist from its target and calls ``solve(q, twist)``; this
wrapper replaces EE ``ee``'s six entries by ``law.twist(those, wrench)``, ``wrench`` the
last reading handed to :meth:`ForceControlled.sense` (tool frame), and calls the
controller it wraps. Everything else (``info``, ``constraints``, ``twist_weight``, the
damping policy...) is the wrapped controller's, read and written through. Its
``loop_tick`` belongs to the wrapped controller, so the loop takes the Python path (the
compiled hot path would skip the law; :meth:`PoseServo.attach_kernel`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .hybrid_force_motion import HybridForceMotion

#: The wrapper's own attributes; every other one is the wrapped controller's.
_OWN = frozenset({"controller", "law", "ee", "wrench"})


class ForceControlled:
    """``controller`` with EE ``ee``'s twist through ``law`` (a :class:`HybridForceMotion`)."""

    def __init__(self, controller: Any, law: HybridForceMotion, ee: int = 0) -> None:
        if not isinstance(ee, int) or ee < 0:
            raise ValueError(f"ee must be an EE index >= 0, got {ee!r}")
        object.__setattr__(self, "controller", controller)
        object.__setattr__(self, "law", law)
        object.__setattr__(self, "ee", ee)
        #: the force/torque sensor's last reading at the EE's tool (tool frame, N and N m)
        object.__setattr__(self, "wrench", np.zeros(6))

    def sense(self, wrench: np.ndarray) -> None:
        """The sensor's reading the next :meth:`solve` uses (6,; not finite: the law
        refuses it there, naming the sensor)."""
        object.__setattr__(self, "wrench", np.array(wrench, dtype=float))

    def solve(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """The wrapped controller's command for ``twist`` with EE :attr:`ee`'s part replaced
        by the law's; ``ValueError`` (the loop's controlled stop) from the law or the
        controller."""
        start = 6 * self.ee
        if twist.shape[0] < start + 6:
            raise ValueError(f"force control on EE {self.ee}: the twist has "
                             f"{twist.shape[0] // 6} EEs")
        shaped = np.array(twist, dtype=float)
        shaped[start:start + 6] = self.law.twist(shaped[start:start + 6], self.wrench)
        return self.controller.solve(q, shaped)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.controller, name)

    def __setattr__(self, name: str, value: Any) -> None:
        if name in _OWN:
            raise AttributeError(f"{name} is fixed at construction (sense() for the wrench)")
        setattr(self.controller, name, value)
