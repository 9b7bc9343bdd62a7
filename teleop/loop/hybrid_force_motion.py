"""Hybrid force/motion in the tool frame (docs/design.md section 21.3).

With every twist a body twist (tool frame, the loop's ``K_p log6(T^-1 T*)``), ``S`` the
diagonal selection of the force-controlled translation axes of the tool frame, ``f`` the
force the tool exerts on the environment (minus the sensor's wrench from the environment,
tool frame) and ``f_d`` the setpoint,

    v = (I - S) v_op + S sat(k_f (f_d - f)),     twist = [v; w_op],

the operator's motion along the free axes and a force loop along the others (its speed
bounded by ``max_speed`` per axis), rotations the operator's. The twist goes to the
controller as the operator's would: the CJM keeps its constraint rows first (the twist is
tracked in their null space), so the law cannot move the instrument off the port. Where
the twist is not feasible there, a heavy task weight on the force axes keeps their
tracking first (docs/design.md section 21.4).

With ``filter_cutoff`` the sensed wrench passes a low-pass filter first
(:class:`~teleop.loop.wrench_filter.WrenchLowPass`), and the stability check takes its lag.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from constraints.validation import as_number

from .force_stability import check_force_gain
from .wrench_filter import WrenchLowPass


class HybridForceMotion:
    """The tool-frame hybrid law of one EE.

    Parameters
    ----------
    force_axes : which of the tool frame's x, y, z are force-controlled (at least one).
    setpoint : (3,) the force to exert on the environment along them, tool frame (N).
    force_gain : ``k_f`` ((m/s)/N), positive.
    contact_stiffness : the stiffest contact expected (N/m), for the stability check.
    dt : the control period (s).
    delay_periods : the periods of delay in the force loop (sensor, servo), at least 1.
    max_speed : the force loop's velocity bound (m/s).
    filter_cutoff : the cut-off (Hz) of the low-pass filter on the sensed wrench, None:
        none.
    filter_order : its first-order sections (1 or 2).
    """

    def __init__(self, force_axes: Sequence[bool], setpoint: Sequence[float],
                 force_gain: float, contact_stiffness: float, dt: float,
                 delay_periods: int = 2, max_speed: float = 0.05,
                 filter_cutoff: float | None = None, filter_order: int = 2) -> None:
        self.set_target(force_axes, setpoint)
        self.force_gain = as_number(force_gain, "force_gain", positive=True)
        self.dt = as_number(dt, "dt", positive=True)
        stiffness = as_number(contact_stiffness, "contact_stiffness", positive=True)
        if not isinstance(delay_periods, int) or delay_periods < 1:
            raise ValueError(f"delay_periods must be an integer >= 1, got {delay_periods!r}")
        self.filter = (None if filter_cutoff is None
                       else WrenchLowPass(filter_cutoff, self.dt, filter_order))
        pole, order = (0.0, 0) if self.filter is None else (self.filter.pole, self.filter.order)
        check_force_gain(self.force_gain, stiffness, self.dt, delay_periods, pole, order)
        self.max_speed = as_number(max_speed, "max_speed", positive=True)

    def set_target(self, force_axes: Sequence[bool], setpoint: Sequence[float]) -> None:
        """The force-controlled axes and the setpoint from now on (``ValueError`` naming
        them; the gain's check does not depend on them)."""
        axes = np.asarray(force_axes)
        if axes.shape != (3,) or axes.dtype != bool or not axes.any():
            raise ValueError(f"force_axes must be 3 booleans, at least one true, got "
                             f"{force_axes!r}")
        target = np.asarray(setpoint, dtype=float)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise ValueError(f"setpoint must be 3 finite forces (N), got {setpoint!r}")
        self.selection = axes.astype(float)
        self.setpoint = target * self.selection

    def twist(self, operator_twist: np.ndarray, wrench: np.ndarray) -> np.ndarray:
        """The commanded body twist ``[v; w]`` (tool frame) from the operator's body twist
        and the sensor's wrench from the environment (tool frame); ``ValueError`` on a
        wrench that is not finite."""
        if not np.all(np.isfinite(wrench)):
            raise ValueError("the force/torque sensor's wrench is not finite")
        if self.filter is not None:
            wrench = self.filter(wrench)
        exerted = -np.asarray(wrench[:3], dtype=float)
        force_velocity = self.force_gain * (self.setpoint - exerted)
        force_velocity = np.clip(force_velocity, -self.max_speed, self.max_speed)
        velocity = (1.0 - self.selection) * operator_twist[:3] \
            + self.selection * force_velocity
        return np.concatenate([velocity, operator_twist[3:]])
