"""Stability of the tool-frame laws in the sampled loop (docs/design.md section 21.3).

A force loop ``v = k_f (f_d - f)`` against a contact of stiffness ``k_c`` is, per control
period ``dt``, an integrator of gain ``g = k_f k_c dt`` closed through ``d`` periods of
delay (the sensor's period, the servo's lag). ``f_{n+1} = f_n + g (f_d - f_{n-d})`` is
stable if and only if ``g < 2 sin(pi / (2 (2 d + 1)))`` (Jury's test on
``z^{d+1} - z^d + g``: 2 without delay, 1 with one period); the laws keep a gain margin of
2 below that bound.

The admittance ``M a + D v + K x = F`` integrated with semi-implicit Euler at ``dt`` has
the characteristic polynomial ``z^2 - (2 - a - b) z + (1 - a)`` with ``a = D dt / M`` and
``b = K dt^2 / M`` (``K`` its spring plus the contact's); its roots are inside the unit
circle if and only if ``0 < a < 2`` and ``2 a + b < 4``.
"""

from __future__ import annotations

import math

#: The laws' gain margin below the sampled stability bound.
GAIN_MARGIN = 2.0


def force_loop_bound(delay_periods: int) -> float:
    """The largest stable ``g = k_f k_c dt`` with ``delay_periods`` periods of delay."""
    return 2.0 * math.sin(math.pi / (2.0 * (2 * delay_periods + 1)))


def check_force_gain(force_gain: float, contact_stiffness: float, dt: float,
                     delay_periods: int) -> None:
    """``ValueError`` naming ``force_gain`` when ``k_f k_c dt`` exceeds the bound over the
    margin."""
    loop_gain = force_gain * contact_stiffness * dt
    allowed = force_loop_bound(delay_periods) / GAIN_MARGIN
    if loop_gain > allowed:
        raise ValueError(
            f"force_gain {force_gain} (m/s)/N is unstable against a contact of "
            f"{contact_stiffness} N/m at dt = {dt} s with {delay_periods} periods of delay: "
            f"k_f k_c dt = {loop_gain:.3g} > {allowed:.3g} (at most "
            f"{allowed / (contact_stiffness * dt):.3g} (m/s)/N)")


def check_admittance(mass: float, damping: float, stiffness: float,
                     contact_stiffness: float, dt: float) -> None:
    """``ValueError`` naming the admittance's parameters when its semi-implicit Euler
    step is not stable with the margin (``a`` and ``2 a + b`` at most half their bounds)."""
    a = damping * dt / mass
    b = (stiffness + contact_stiffness) * dt * dt / mass
    if not (a <= 2.0 / GAIN_MARGIN and 2.0 * a + b <= 4.0 / GAIN_MARGIN):
        raise ValueError(
            f"admittance mass {mass} kg, damping {damping} N s/m, stiffness {stiffness} N/m "
            f"is unstable at dt = {dt} s against {contact_stiffness} N/m of contact: "
            f"D dt / M = {a:.3g} (at most {2.0 / GAIN_MARGIN:.3g}), 2 D dt / M + "
            f"K dt^2 / M = {2.0 * a + b:.3g} (at most {4.0 / GAIN_MARGIN:.3g}); raise the mass")
