"""Constraint types whose evaluation is affine in a world point and its velocity, so the
analytical CJM precomputes their per-step terms as one matrix product (docs/design.md
section 16).

A type registers an :class:`AffineForm` here (:func:`register_affine_form`): its
``anchor`` ``[x_w; f_w]`` (6,), a world point and its world velocity, and its evaluation as
a function of ``x = T_a^-1 x_w`` and ``f = R_a^T f_w`` (``p``, ``error`` and ``rhs`` affine
in ``(x, f)`` at a fixed gain, ``C`` and ``C_perp`` constant). The lookup walks the type's
bases, and a subclass that overrides a method of its base's math
(:func:`constraints.math_methods.keeps_math`) has no form, as a type without one: it is
evaluated at every step, by its own math.
"""

from __future__ import annotations

from typing import Any, Protocol, TypeVar

import numpy as np
import pinocchio as pin

from constraints import Constraint, ConstraintPoint, Hole
from constraints.math_methods import keeps_math

#: the constraint type an affine form is registered for
C = TypeVar("C", bound=Constraint, contravariant=True)


class AffineForm(Protocol[C]):
    """How one constraint type's evaluation is affine in its anchor."""

    def anchor(self, constraint: C) -> np.ndarray:
        """``[x_w; f_w]`` (6,), read-only and replaced (never edited) whenever the
        geometry changes."""
        ...

    def evaluate(self, constraint: C, x: np.ndarray, f: np.ndarray | None) -> ConstraintPoint:
        """The constraint's evaluation at ``x`` and ``f`` (``F_a`` coordinates; ``f`` None
        at rest)."""
        ...


class HoleCentre:
    """A hole: its centre and the centre's velocity (``p = (e . x) e``, ``error = -C x``,
    ``rhs = K C x + C f``)."""

    def anchor(self, hole: Hole) -> np.ndarray:
        """The hole's :attr:`~constraints.Hole.anchor`."""
        return hole.anchor

    def evaluate(self, hole: Hole, x: np.ndarray, f: np.ndarray | None) -> ConstraintPoint:
        """:meth:`constraints.Hole.evaluate_local`."""
        return hole.evaluate_local(x, f)


#: constraint type -> its affine form (the nearest registered base of a type decides)
AFFINE_FORMS: dict[type[Constraint], AffineForm[Any]] = {}


def register_affine_form(constraint_type: type[C], form: AffineForm[C]) -> None:
    """Precompute the terms of ``constraint_type`` (and of its subclasses that keep its
    math) through ``form``."""
    AFFINE_FORMS[constraint_type] = form


def affine_form_of(constraint: Constraint) -> AffineForm[Any] | None:
    """The affine form of ``constraint``'s type (its nearest registered base's, when the
    type keeps that base's math), or None."""
    kind = type(constraint)
    declaring = next((base for base in kind.__mro__ if base in AFFINE_FORMS), None)
    if declaring is None or not keeps_math(kind, declaring):
        return None
    return AFFINE_FORMS[declaring]


def affine_inputs(form: AffineForm[Any], constraint: Constraint,
                  placement: pin.SE3) -> tuple[np.ndarray, np.ndarray | None]:
    """``(x, f)`` of ``form``'s anchor in the coordinates of the link at ``placement``
    (``f`` None at rest)."""
    anchor = form.anchor(constraint)
    velocity = anchor[3:]
    return (placement.actInv(anchor[:3]),
            placement.rotation.T @ velocity if velocity.any() else None)


register_affine_form(Hole, HoleCentre())
