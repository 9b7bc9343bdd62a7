"""The robot's command interface on the physics plant (docs/design.md section 17.1,
"The interface"): a velocity interface that refuses a command beyond the robot's joint
acceleration or jerk limits, as a Franka's does (``joint_motion_generator_velocity_
discontinuity``, ``..._acceleration_discontinuity``: the robot stops with a reflex error).

Each period the interface receives one joint velocity command ``v_k`` (after the latency)
and differentiates it against the last command it accepted,

    a_k = (v_k - v_{k-1}) / dt,    j_k = (a_k - a_{k-1}) / dt,    v_{-1} = a_{-1} = 0,

and finds a fault where some joint has ``|a_k| > (1 + INTERFACE_TOLERANCE) a_max`` or
``|j_k| > (1 + INTERFACE_TOLERANCE) j_max``. The modes (:data:`INTERFACE_MODES`):
``off`` checks nothing; ``count`` counts the faults and passes every command on (a monitor:
the robot is not stopped); ``strict`` stops the robot at the first fault: that command and
every later one become zero velocity (the drives hold their references) and nothing more
is checked, so a strict run has at most one fault.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

#: The interface's modes, by name (the plant setting ``interface_limits``).
INTERFACE_MODES = ("off", "count", "strict")

#: Relative tolerance on the acceleration and jerk limits: a command is refused beyond
#: ``(1 + 1%)`` of a limit. A controller that keeps the limits returns commands inside its
#: box to its solver's tolerance (1e-9 rad/s, 1e-6 rad/s^2 at 1 kHz); 1% is above that by
#: orders of magnitude and far below the violations that matter (issue 32: 2,658 rad/s^2
#: against limits of 5-20 rad/s^2). libfranka checks its limits with an absolute margin of
#: ``kLimitEps = 1e-3`` in the same units.
INTERFACE_TOLERANCE = 0.01


@dataclass(frozen=True)
class InterfaceFault:
    """One refused command: the period (counted from the plant's reset), the joint, what
    was exceeded (``acceleration`` or ``jerk``), the command's value and the limit (rad/s^2
    or rad/s^3; m/s^2, m/s^3 on a prismatic or base joint)."""

    period: int
    joint: str
    quantity: str
    value: float
    limit: float

    def describe(self) -> str:
        """In words: ``joint_2 acceleration 31.2 rad/s^2 beyond its limit 10 (+1%)``."""
        unit = "rad/s^2" if self.quantity == "acceleration" else "rad/s^3"
        return (f"{self.joint} {self.quantity} {self.value:.4g} {unit} beyond its limit "
                f"{self.limit:.4g} (+{100 * INTERFACE_TOLERANCE:g}%)")


def velocity_names(model: pin.Model) -> list[str]:
    """One name per velocity coordinate: the joint's, with ``[i]`` on a multi-dof joint."""
    names = []
    for joint in range(1, model.njoints):
        count = model.nvs[joint]
        names += ([model.names[joint]] if count == 1
                  else [f"{model.names[joint]}[{i}]" for i in range(count)])
    return names


class CommandInterface:
    """The check of :mod:`teleop.plants.interface` for one run (docs/design.md 17.1).

    Parameters
    ----------
    mode : one of :data:`INTERFACE_MODES`.
    model : the robot's Pinocchio model (the joints' names).
    dt : the control period (s).
    acceleration_limit : (nv,) per-joint limits (``inf``: none), or None: not checked.
    jerk_limit : one limit for every joint, or None: not checked.
    """

    def __init__(self, mode: str, model: pin.Model, dt: float,
                 acceleration_limit: np.ndarray | None, jerk_limit: float | None) -> None:
        if mode not in INTERFACE_MODES:
            raise ValueError(f"interface_limits must be one of {', '.join(INTERFACE_MODES)}, "
                             f"got {mode!r}")
        if mode != "off" and acceleration_limit is None and jerk_limit is None:
            raise ValueError(f"interface_limits {mode} needs the robot's acceleration limits "
                             "or interface_jerk_limit: this robot has neither")
        self.mode = mode
        self.dt = float(dt)
        self.names = velocity_names(model)
        nv = model.nv
        scale = 1.0 + INTERFACE_TOLERANCE
        self._acceleration_limit = (np.full(nv, np.inf) if acceleration_limit is None
                                    else np.asarray(acceleration_limit, dtype=float))
        self._jerk_limit = np.full(nv, np.inf if jerk_limit is None else float(jerk_limit))
        self._acceleration_bound = scale * self._acceleration_limit
        self._jerk_bound = scale * self._jerk_limit
        self.reset()

    def reset(self) -> None:
        """At rest: no command accepted yet, not stopped, no fault."""
        nv = len(self.names)
        self._velocity, self._acceleration = np.zeros(nv), np.zeros(nv)
        self._period = 0
        self.stopped = False
        self.faults = 0
        self.first_fault: InterfaceFault | None = None

    def receive(self, command: np.ndarray) -> tuple[np.ndarray, InterfaceFault | None]:
        """The velocity the drives get this period, and this period's fault (None: none)."""
        period = self._period
        self._period += 1
        if self.mode == "off":
            return command, None
        if self.stopped:
            return np.zeros_like(command), None
        acceleration = (command - self._velocity) / self.dt
        jerk = (acceleration - self._acceleration) / self.dt
        fault = (self._fault(period, "acceleration", acceleration, self._acceleration_bound,
                             self._acceleration_limit)
                 or self._fault(period, "jerk", jerk, self._jerk_bound, self._jerk_limit))
        if fault is not None:
            self.faults += 1
            if self.first_fault is None:
                self.first_fault = fault
            if self.mode == "strict":
                self.stopped = True
                return np.zeros_like(command), fault
        self._velocity, self._acceleration = np.array(command, dtype=float), acceleration
        return command, fault

    def _fault(self, period: int, quantity: str, values: np.ndarray, bound: np.ndarray,
               limit: np.ndarray) -> InterfaceFault | None:
        """The joint furthest beyond its bound (relative to its limit), or None."""
        excess = np.abs(values) - bound
        if not np.any(excess > 0):
            return None
        joint = int(np.argmax(np.where(excess > 0, excess / limit, -np.inf)))
        return InterfaceFault(period, self.names[joint], quantity, float(values[joint]),
                              float(limit[joint]))
