"""What the compiled CJM step computes each constraint type's terms from (docs/design.md
section 16), registered here by constraint type.

A type whose math the extension repeats in C++ (``controllers/cjm/_step/terms.cpp``)
registers a :class:`CompiledForm` (:func:`register_compiled_form`): the extension's name of
its terms and its parameters as one float64 array taken from its fields (each kind's
layout in ``controllers/cjm/_step/terms.hpp``). The step takes the parameters again
whenever the constraint's ``revision`` is replaced (:mod:`constraints.revision`). The
lookup walks the type's bases; a subclass that overrides a method of its math
(:func:`constraints.math_methods.keeps_math`) gets no form (the kind's math would not be
its math: Python writes its terms), nor does a type registered nowhere.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Any, Callable, Generic, TypeVar

import numpy as np

from constraints import Constraint, Hole, Plane, PointLock
from constraints.math_methods import keeps_math

#: how far from 1 the norm of a declared axis or normal may be (as
#: :func:`constraints.validation.as_unit_vector` accepts it); the compiled step checks it
UNIT_TOLERANCE = 1e-6

#: the constraint type a compiled form is registered for
C = TypeVar("C", bound=Constraint)


@dataclass(frozen=True)
class CompiledForm(Generic[C]):
    """What the compiled step computes one constraint type's terms from.

    Attributes
    ----------
    kind : the extension's name of the terms ("hole", "plane", "point_lock"; a barrier's
        are a plane's, its rows inequalities).
    values : the kind's parameters from a constraint's fields, a new float64 array.
    """

    kind: str
    values: Callable[[C], np.ndarray]


#: constraint type -> its compiled form (the nearest registered base of a type decides)
COMPILED_FORMS: dict[type[Constraint], CompiledForm[Any]] = {}


def register_compiled_form(constraint_type: type[C], form: CompiledForm[C]) -> None:
    """Compute the terms of ``constraint_type`` (and of subclasses without their own
    math) in C++ from ``form``."""
    COMPILED_FORMS[constraint_type] = form
    form_of_type.cache_clear()


@cache
def form_of_type(constraint_type: type[Constraint]) -> CompiledForm[Any] | None:
    """The compiled form of ``constraint_type``: its nearest registered base's, when the
    type keeps that base's math (:func:`~constraints.math_methods.keeps_math`); else None."""
    declaring = next((kind for kind in constraint_type.__mro__ if kind in COMPILED_FORMS), None)
    if declaring is None or not keeps_math(constraint_type, declaring):
        return None
    return COMPILED_FORMS[declaring]


def compiled_form_of(constraint: Constraint) -> CompiledForm[Any] | None:
    """How the compiled step computes ``constraint``'s terms, or None (Python writes them)."""
    return form_of_type(type(constraint))


def hole_values(hole: Hole) -> np.ndarray:
    """``[center, velocity, link_axis, gain]`` (10,), world frame but the axis."""
    return np.concatenate([hole.anchor, hole.link_axis, [hole.gain]])


def plane_values(plane: Plane) -> np.ndarray:
    """``[link_point, plane_point, normal, velocity, gain]`` (13,); a barrier's the same."""
    return np.concatenate([plane.link_point, plane.plane_point, plane.normal, plane.velocity,
                           [plane.gain]])


def point_lock_values(lock: PointLock) -> np.ndarray:
    """``[link_point, target, velocity, gain]`` (10,)."""
    return np.concatenate([lock.link_point, lock.target, lock.velocity, [lock.gain]])


register_compiled_form(Hole, CompiledForm("hole", hole_values))
register_compiled_form(Plane, CompiledForm("plane", plane_values))
register_compiled_form(PointLock, CompiledForm("point_lock", point_lock_values))
