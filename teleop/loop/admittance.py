"""An admittance at the tool (docs/design.md section 21.3): a virtual mass-damper-spring
driven by the measured wrench,

    M a + D v + K x = F,

per translation axis of the tool frame, with ``x`` the tool's offset from the operator's
motion and ``F`` the sensor's force from the environment. Each period integrates it with
semi-implicit Euler (``v += dt (F - D v - K x) / M``, then ``x += dt v``) and adds ``v``
to the operator's body twist (tool frame). At rest ``x = F / K``: a push of ``F`` moves the tool by ``F / K``.

With ``filter_cutoff`` the sensed wrench passes a low-pass filter first
(:class:`~teleop.loop.wrench_filter.WrenchLowPass`, as the hybrid law's), and the stability
check takes its lag on the contact's force (:func:`~teleop.loop.force_stability.check_admittance`).
"""

from __future__ import annotations

import numpy as np

from constraints.validation import as_number

from .force_stability import check_admittance
from .wrench_filter import WrenchLowPass


class Admittance:
    """The tool-frame admittance of one EE.

    Parameters
    ----------
    mass : ``M`` (kg), damping ``D`` (N s/m), stiffness ``K`` (N/m): positive.
    contact_stiffness : the stiffest contact expected (N/m), for the stability check.
    dt : the control period (s).
    filter_cutoff : the cut-off (Hz) of the low-pass filter on the sensed wrench, None:
        unfiltered.
    filter_order : its first-order sections (1 or 2).
    """

    def __init__(self, mass: float, damping: float, stiffness: float,
                 contact_stiffness: float, dt: float, filter_cutoff: float | None = None,
                 filter_order: int = 2) -> None:
        self.mass = as_number(mass, "admittance mass", positive=True)
        self.damping = as_number(damping, "admittance damping", positive=True)
        self.stiffness = as_number(stiffness, "admittance stiffness", positive=True)
        self.dt = as_number(dt, "dt", positive=True)
        self.filter = (None if filter_cutoff is None
                       else WrenchLowPass(filter_cutoff, self.dt, filter_order))
        pole, order = (0.0, 0) if self.filter is None else (self.filter.pole, self.filter.order)
        check_admittance(self.mass, self.damping, self.stiffness,
                         as_number(contact_stiffness, "contact_stiffness", 0.0), self.dt,
                         pole, order)
        self.offset = np.zeros(3)
        self.velocity = np.zeros(3)

    def reset(self) -> None:
        """At rest on the operator's motion, the filter (if any) waiting for a reading."""
        self.offset[:] = 0.0
        self.velocity[:] = 0.0
        if self.filter is not None:
            self.filter.reset()

    def twist(self, operator_twist: np.ndarray, wrench: np.ndarray) -> np.ndarray:
        """The commanded body twist: the operator's plus the admittance's velocity (tool
        frame, as the wrench); ``ValueError`` on a wrench that is not finite."""
        if not np.all(np.isfinite(wrench)):
            raise ValueError("the force/torque sensor's wrench is not finite")
        if self.filter is not None:
            wrench = self.filter(wrench)
        force = np.asarray(wrench[:3], dtype=float)
        self.velocity += self.dt * (force - self.damping * self.velocity
                                    - self.stiffness * self.offset) / self.mass
        self.offset += self.dt * self.velocity
        twist = np.array(operator_twist, dtype=float)
        twist[:3] += self.velocity
        return twist
