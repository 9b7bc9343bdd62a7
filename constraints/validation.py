"""Input checks shared by every layer: bad input raises ``ValueError`` naming the argument.

This is the bottom package, so the controllers, the loop, the experiments and the UI all
validate through these few functions instead of their own copies.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from numbers import Real

import numpy as np


def as_number(value, name: str, minimum: float | None = None, *, positive: bool = False,
              maximum: float | None = None) -> float:
    """``value`` as a finite float, else ``ValueError`` naming ``name``.

    ``None``, strings, lists and booleans are refused (they are almost always a caller's
    mistake, and ``float("1e3")`` would hide it). ``minimum`` is inclusive, ``positive``
    asks for ``> 0``, ``maximum`` is inclusive.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (Real, np.number)) \
            or isinstance(value, np.complexfloating):
        raise ValueError(f"{name} must be a number, got {short_repr(value)}")
    try:
        number = float(value)
    except OverflowError:  # an int beyond float's range, such as JSON's 10**400
        raise ValueError(f"{name} must be finite, got an integer of {len(str(value))} digits") from None
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {number}")
    if positive and not number > 0.0:
        raise ValueError(f"{name} must be > 0, got {number:g}")
    if minimum is not None and number < minimum:
        raise ValueError(f"{name} must be >= {minimum:g}, got {number:g}")
    if maximum is not None and number > maximum:
        raise ValueError(f"{name} must be <= {maximum:g}, got {number:g}")
    return number


#: ``numpy.dtype.kind`` of the arrays :func:`as_vector` reads: floats, signed and unsigned
#: integers (not complex, booleans, strings or objects)
REAL_KINDS = "fiu"


def as_vector(value, size: int, name: str, maximum: float | None = None) -> np.ndarray:
    """``value`` as a new finite float array of shape ``(size,)``, else ``ValueError``.

    Only real numbers are read: a complex array (whose imaginary part a float cast would
    drop), booleans, strings, ``None`` or other objects are refused. ``maximum`` bounds
    each component's magnitude (inclusive).
    """
    try:
        array = np.asarray(value)
    except (TypeError, ValueError, OverflowError, RecursionError):  # ragged, odd objects
        array = None
    if isinstance(value, (list, tuple)) and any(isinstance(item, (bool, np.bool_))
                                                for item in value):
        array = None  # [True, 0, 0] is an integer array to NumPy
    if array is None or array.dtype.kind not in REAL_KINDS:
        raise ValueError(f"{name} must be an array of {size} numbers, got {short_repr(value)}")
    array = np.array(array, dtype=float)
    if array.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite, got {short_repr(array.tolist())}")
    if maximum is not None and np.abs(array).max(initial=0.0) > maximum:
        raise ValueError(f"{name} must have every component in [-{maximum:g}, {maximum:g}], "
                         f"got {short_repr(array.tolist())}")
    return array


def as_settings(value, name: str) -> dict:
    """``value`` as a dict of keyword settings (string keys; values numbers, booleans or
    strings, numbers finite), else ``ValueError`` naming ``name``. None is no settings."""
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise ValueError(f"{name} must be a mapping of setting names to values, got "
                         f"{short_repr(value)}")
    for key, item in value.items():
        if not isinstance(key, str) or not key.isidentifier():
            raise ValueError(f"{name} keys must be setting names, got {short_repr(key)}")
        if not isinstance(item, (str, bool, np.bool_)):
            as_number(item, f"{name}[{key!r}]")
    return dict(value)


def as_unit_vector(value, name: str, tolerance: float = 1e-6) -> np.ndarray:
    """``value`` as a unit 3-vector; zero or non-unit vectors raise ``ValueError``.

    A vector whose norm differs from one by more than ``tolerance`` is refused rather than
    silently normalised: a normal of norm 2 is almost always a bug in the caller.
    """
    vector = as_vector(value, 3, name)
    norm = float(np.linalg.norm(vector))
    if norm < 1e-12:
        raise ValueError(f"{name} must be a unit vector, got the zero vector")
    if abs(norm - 1.0) > tolerance:
        raise ValueError(f"{name} must be a unit vector, got norm {norm:.6g}")
    return vector / norm


def short_repr(value, limit: int = 80) -> str:
    """``repr(value)`` cut to ``limit`` characters, so an error message stays one line."""
    try:
        text = " ".join(repr(value).split())
    except (RecursionError, ValueError):  # nested too deeply; an int too long to print
        return f"a {type(value).__name__} too large to show"
    return text if len(text) <= limit else text[:limit - 3] + "..."
