"""Joint acceleration limits: the braking-aware position bound and the acceleration box
(docs/design.md section 8.4), and the braking-aware velocity dampers of the barriers and
the collision pairs (sections 12 and 18.3)."""

from __future__ import annotations

import dataclasses

import numpy as np

from constraints.collision import CollisionAvoidance, CollisionRows
from constraints.validation import REAL_KINDS, short_repr


def as_acceleration_limit(value, size: int, name: str = "acceleration_limit") -> np.ndarray | None:
    """``value`` as a new float array (size,) of positive limits (``inf``: none for that
    joint), or None for None (no acceleration limit); else ``ValueError`` naming ``name``."""
    if value is None:
        return None
    try:
        array = np.asarray(value)
    except (TypeError, ValueError, OverflowError, RecursionError):
        array = None
    if array is None or array.dtype.kind not in REAL_KINDS:
        raise ValueError(f"{name} must be an array of {size} numbers, got {short_repr(value)}")
    array = np.array(array, dtype=float)
    if array.ndim == 0:
        array = np.full(size, float(array))
    if array.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {array.shape}")
    if np.isnan(array).any() or (array <= 0.0).any():
        raise ValueError(f"{name} must be positive (inf: no limit), got {short_repr(array.tolist())}")
    return array


#: the relative margin the braking bound is rounded down by: it covers the roundings of
#: ``d / (a dt^2)`` and back, and of the caller's ``v dt`` (about 8 half-ulps)
ROUNDING_MARGIN = 8.0 * np.finfo(float).eps
#: below it a double is subnormal: its relative precision is lost
SMALLEST_NORMAL = np.finfo(float).tiny


def braking_speed(distance: np.ndarray, step: np.ndarray, dt: float, gain: float) -> np.ndarray:
    """The largest speed (>= 0) towards a position limit ``distance >= 0`` away from which
    the joint can still stop, slowing by ``step = a dt`` per period, with every period
    covering at most the fraction ``gain`` of the distance left (docs/design.md 8.4).

    In units ``x = v / (a dt)``, ``D = d / (a dt^2)``, ``c = 1 / gain``, braking at once from
    ``x`` needs ``T(x) = max_k [sum_{j<k} (x - j) + (x - k) c] <= D``, i.e. ``x <= x_k(D) =
    (D + k (k - 1) / 2 + k c) / (k + c)`` for every integer ``k >= 0``. ``x_k`` is convex in
    ``k``, least at ``k* = sqrt(2 D + c - c^2) - c``: the bound is the least of ``x_0 = g D``
    and ``x_k`` at the two integers around ``k*``. The set is invariant: from ``x`` inside
    at ``D``, ``x - 1`` is inside at ``D - x``, so braking is always possible.

    Rounding errs on the safe side: the bound is rounded down by :data:`ROUNDING_MARGIN`
    (so ``bound * dt`` never exceeds ``gain * distance`` by an ulp), and a bound below the
    smallest normal double, which has lost its relative precision, is 0.
    """
    c = 1.0 / gain
    scaled = distance / (step * dt)
    k = np.floor(np.maximum(np.sqrt(np.maximum(2.0 * scaled + c - c * c, 0.0)) - c, 0.0))
    x_0 = scaled / c
    x_k = (scaled + k * (k - 1.0) / 2.0 + k * c) / (k + c)
    k = k + 1.0
    x_next = (scaled + k * (k - 1.0) / 2.0 + k * c) / (k + c)
    bound = step * np.minimum(np.minimum(x_0, x_k), x_next) * (1.0 - ROUNDING_MARGIN)
    bound[bound < SMALLEST_NORMAL] = 0.0
    return bound


def give_way(lower: np.ndarray, upper: np.ndarray, window_lower: np.ndarray,
             window_upper: np.ndarray) -> None:
    """Where the window ``[window_lower, window_upper]`` (changed in place) misses the box
    ``[lower, upper]``, the window becomes the point of the box nearest to it: the limit
    the window stands for gives way to the box's."""
    miss = (window_lower > upper) | (window_upper < lower)
    if miss.any():
        point = np.minimum(np.maximum(np.minimum(np.maximum(lower, window_lower), window_upper),
                                      lower), upper)
        window_lower[miss] = point[miss]
        window_upper[miss] = point[miss]


def acceleration_box(lower: np.ndarray, upper: np.ndarray, previous: np.ndarray,
                     step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[previous - a dt, previous + a dt]`` (new arrays); where it misses the box
    ``[lower, upper]`` of the position and velocity limits, the point of that box nearest
    to it: the acceleration limit gives way, never the position or velocity limits."""
    accel_lower, accel_upper = previous - step, previous + step
    give_way(lower, upper, accel_lower, accel_upper)
    return accel_lower, accel_upper


def jerk_box(lower: np.ndarray, upper: np.ndarray, previous: np.ndarray,
             previous_change: np.ndarray, step: np.ndarray,
             velocity_limit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box ``[lower, upper]`` (the position, velocity and acceleration limits'; new
    arrays) cut to the jerk window (docs/design.md 8.5): the command's change within
    ``previous_change +- step`` (``step = j dt^2``), and no larger towards a velocity limit
    than the change that can still fall to zero, by ``step`` a period, before the limit:
    :func:`braking_speed` with the command as the position, its change per period as the
    speed and ``step`` as the braking step. Where the window misses the box, the point of
    the box nearest to it: the jerk limit gives way to the other limits, never they to it
    (at a position limit the braking is the acceleration limits', without jerk)."""
    centre = previous + previous_change
    jerk_lower, jerk_upper = centre - step, centre + step
    limited = np.isfinite(velocity_limit)
    if limited.any():
        room_up = np.maximum(velocity_limit[limited] - previous[limited], 0.0)
        room_down = np.maximum(velocity_limit[limited] + previous[limited], 0.0)
        jerk_upper[limited] = np.minimum(
            jerk_upper[limited], previous[limited] + braking_speed(room_up, step[limited], 1.0, 1.0))
        jerk_lower[limited] = np.maximum(
            jerk_lower[limited], previous[limited] - braking_speed(room_down, step[limited], 1.0, 1.0))
        np.minimum(jerk_lower, jerk_upper, out=jerk_lower)  # rounding: never an empty window
    give_way(lower, upper, jerk_lower, jerk_upper)
    return np.maximum(lower, jerk_lower), np.minimum(upper, jerk_upper)


#: The share of the deceleration its joints could give a point along a damper's row, at
#: their acceleration limits, that the braking-aware damper counts on (docs/design.md 12):
#: the rest is left to the other rows the same joints hold (a trocar, a second barrier or
#: pair on the same joints) and to the row turning with ``q`` between two steps.
DAMPER_BRAKING_SHARE = 0.5


def damper_deceleration(rows: np.ndarray, acceleration_limit: np.ndarray) -> np.ndarray:
    """Per row ``r`` of ``rows`` (m, nv): ``a_n = DAMPER_BRAKING_SHARE * sum_i |r_i| a_i``,
    the deceleration (m/s^2) the damper counts on along the row (docs/design.md 12); ``inf``
    where a joint without an acceleration limit moves the point, 0 where no joint does."""
    reach = np.abs(rows) * np.where(rows != 0.0, acceleration_limit, 0.0)
    return DAMPER_BRAKING_SHARE * reach.sum(axis=1)


def braked_lower(rows: np.ndarray, lower: np.ndarray, gaps: np.ndarray, gains: np.ndarray,
                 acceleration_limit: np.ndarray | None, dt: float) -> np.ndarray:
    """The bounds of velocity dampers ``rows qd >= lower`` (``lower = f - K g``: a gap
    ``g`` closing at most at ``K g``, ``f`` the fed-forward velocity) made braking-aware
    (docs/design.md 12, 18.3): where ``g > 0`` the allowed approach is ``min(K g, s)``, ``s``
    the :func:`braking_speed` for ``g`` with the deceleration ``a_n`` of
    :func:`damper_deceleration` (step ``a_n dt``, every period covering at most ``K dt`` of
    the gap), so ``lower`` is raised by ``K g - s >= 0``. ``lower`` itself (not a copy)
    without acceleration limits, where nothing is raised."""
    if acceleration_limit is None or not lower.size:
        return lower
    deceleration = damper_deceleration(rows, acceleration_limit)
    braked = (gaps > 0.0) & (gains > 0.0) & (deceleration > 0.0) & np.isfinite(deceleration)
    if not braked.any():
        return lower
    gap, gain = gaps[braked], gains[braked]
    raised = lower.copy()
    raised[braked] += gain * gap - braking_speed(gap, deceleration[braked] * dt, dt, gain * dt)
    return raised


def braked_pairs(pairs: CollisionRows, avoidance: CollisionAvoidance,
                 acceleration_limit: np.ndarray | None, dt: float) -> CollisionRows:
    """The collision rows with their bounds made braking-aware (:func:`braked_lower`, the
    gap ``d - d_s`` at the avoidance's rate); ``pairs`` itself where nothing is raised."""
    lower = braked_lower(pairs.rows, pairs.lower, pairs.distances - avoidance.safety_distance,
                         np.full(pairs.size, avoidance.gain), acceleration_limit, dt)
    return pairs if lower is pairs.lower else dataclasses.replace(pairs, lower=lower)
