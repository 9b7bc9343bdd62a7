"""Stability of the tool-frame laws in the sampled loop (docs/design.md section 21.3).

A force loop ``v = k_f (f_d - f)`` against a contact of stiffness ``k_c`` is, per control
period ``dt``, an integrator of gain ``g = k_f k_c dt`` closed through ``d`` periods of
delay (the sensor's period, the servo's lag). ``f_{n+1} = f_n + g (f_d - f_{n-d})`` is
stable if and only if ``g < 2 sin(pi / (2 (2 d + 1)))`` (Jury's test on
``z^{d+1} - z^d + g``: 2 without delay, 1 with one period); the laws keep a gain margin of
2 below that bound.

A low-pass filter on the sensed force (:class:`teleop.loop.wrench_filter.WrenchLowPass`,
``m`` sections ``alpha z / (z - beta)``, ``alpha = 1 - beta``) closes the loop through
``z^-d H(z)^m``: the characteristic polynomial is

    (z - 1) (z - beta)^m z^d + g alpha^m z^m,

whose largest stable ``g`` has no closed form; it is found by a scan of ``g`` in (0, 4]
(the polynomial's roots, ``numpy.roots``) to the first unstable gain, then bisection.
Without a filter (``m = 0`` or ``beta = 0``) it is the closed form above.

The admittance ``M a + D v + K x = F`` integrated with semi-implicit Euler at ``dt`` has
the characteristic polynomial ``z^2 - (2 - a - b) z + (1 - a)`` with ``a = D dt / M`` and
``b = K dt^2 / M`` (``K`` its spring plus the contact's); its roots are inside the unit
circle if and only if ``0 < a < 2`` and ``2 a + b < 4``. The margin asks that of ``2 a``
and ``2 b`` (half the mass). With the contact's force ``F = -k_c x`` through the
filter, the polynomial becomes (``b_K = K dt^2 / M``, ``b_c = k_c dt^2 / M``)::

    ((z - 1 + a) (z - 1) + b_K z) (z - beta)^m + b_c alpha^m z^(m + 1),

and the margin asks its roots inside the unit circle at ``2 a``, ``2 b_K`` and ``2 b_c``.
Without a filter that is the closed form above.
"""

from __future__ import annotations

import math

import numpy as np

#: The laws' gain margin below the sampled stability bound.
GAIN_MARGIN = 2.0


#: The scan's gains before the bisection, and the bisection's steps.
SCAN_POINTS, BISECTION_STEPS = 400, 50


def _filtered_loop_stable(gain: float, delay_periods: int, pole: float, order: int) -> bool:
    """Every root of ``(z - 1) (z - beta)^m z^d + g alpha^m z^m`` inside the unit circle."""
    polynomial = np.polymul(np.polymul([1.0, -1.0], np.poly([pole] * order)),
                            [1.0] + [0.0] * delay_periods)
    polynomial[len(polynomial) - 1 - order] += gain * (1.0 - pole) ** order
    return bool(np.max(np.abs(np.roots(polynomial))) < 1.0)


def force_loop_bound(delay_periods: int, filter_pole: float = 0.0,
                     filter_order: int = 0) -> float:
    """The largest stable ``g = k_f k_c dt`` with ``delay_periods`` periods of delay and
    ``filter_order`` low-pass sections of pole ``filter_pole`` on the sensed force."""
    if filter_order == 0 or filter_pole == 0.0:
        return 2.0 * math.sin(math.pi / (2.0 * (2 * delay_periods + 1)))
    gains = np.linspace(4.0 / SCAN_POINTS, 4.0, SCAN_POINTS)
    stable, unstable = 0.0, 4.0
    for gain in gains:
        if not _filtered_loop_stable(float(gain), delay_periods, filter_pole, filter_order):
            unstable = float(gain)
            break
        stable = float(gain)
    for _ in range(BISECTION_STEPS):
        middle = 0.5 * (stable + unstable)
        if _filtered_loop_stable(middle, delay_periods, filter_pole, filter_order):
            stable = middle
        else:
            unstable = middle
    return stable


def check_force_gain(force_gain: float, contact_stiffness: float, dt: float,
                     delay_periods: int, filter_pole: float = 0.0,
                     filter_order: int = 0) -> None:
    """``ValueError`` naming ``force_gain`` when ``k_f k_c dt`` exceeds the bound (with the
    force filter's lag, :func:`force_loop_bound`) over the margin."""
    loop_gain = force_gain * contact_stiffness * dt
    allowed = force_loop_bound(delay_periods, filter_pole, filter_order) / GAIN_MARGIN
    if loop_gain > allowed:
        filtered = (f" and a {filter_order}-section force filter of pole {filter_pole:.4g}"
                    if filter_order else "")
        raise ValueError(
            f"force_gain {force_gain} (m/s)/N is unstable against a contact of "
            f"{contact_stiffness} N/m at dt = {dt} s with {delay_periods} periods of delay"
            f"{filtered}: k_f k_c dt = {loop_gain:.3g} > {allowed:.3g} (at most "
            f"{allowed / (contact_stiffness * dt):.3g} (m/s)/N)")


def admittance_polynomial(a: float, spring: float, contact: float, pole: float = 0.0,
                          order: int = 0) -> np.ndarray:
    """The admittance's characteristic polynomial (module docstring) with ``a = D dt / M``,
    ``spring = K dt^2 / M``, ``contact = k_c dt^2 / M`` and ``order`` filter sections of
    pole ``pole`` on the contact's force (highest power first)."""
    own = np.polyadd(np.polymul([1.0, a - 1.0], [1.0, -1.0]), [spring, 0.0])
    polynomial = np.polymul(own, np.poly([pole] * order))
    polynomial[len(polynomial) - 2 - order] += contact * (1.0 - pole) ** order
    return polynomial


def check_admittance(mass: float, damping: float, stiffness: float,
                     contact_stiffness: float, dt: float, filter_pole: float = 0.0,
                     filter_order: int = 0) -> None:
    """``ValueError`` naming the admittance's parameters when its semi-implicit Euler
    step is not stable with the margin (without a filter: ``a`` and ``2 a + b`` at most half
    their bounds; with ``filter_order`` sections of pole ``filter_pole`` on the sensed
    force, the roots of :func:`admittance_polynomial` at twice ``a`` and ``b``)."""
    a = damping * dt / mass
    spring, contact = stiffness * dt * dt / mass, contact_stiffness * dt * dt / mass
    b = spring + contact
    if filter_order == 0 or filter_pole == 0.0:
        stable = a <= 2.0 / GAIN_MARGIN and 2.0 * a + b <= 4.0 / GAIN_MARGIN
        bounds = (f"D dt / M = {a:.3g} (at most {2.0 / GAIN_MARGIN:.3g}), 2 D dt / M + "
                  f"K dt^2 / M = {2.0 * a + b:.3g} (at most {4.0 / GAIN_MARGIN:.3g})")
    else:
        polynomial = admittance_polynomial(GAIN_MARGIN * a, GAIN_MARGIN * spring,
                                           GAIN_MARGIN * contact, filter_pole, filter_order)
        radius = float(np.max(np.abs(np.roots(polynomial))))
        stable = radius < 1.0
        bounds = (f"with a {filter_order}-section force filter of pole {filter_pole:.4g}, "
                  f"its roots at half the mass reach {radius:.4g} (below 1 needed)")
    if not stable:
        raise ValueError(
            f"admittance mass {mass} kg, damping {damping} N s/m, stiffness {stiffness} N/m "
            f"is unstable at dt = {dt} s against {contact_stiffness} N/m of contact: "
            f"{bounds}; raise the mass")
