"""A constraint type's evaluation over many periods at once, for the measures taken after a
run (docs/design.md 5.1, :mod:`teleop.loop.measured_in_batches`).

Each period keeps its own copy of a constraint (its geometry of that instant) and the
placement ``T_a = (R, t)`` of its link; the measures read the evaluation of section 3 at
each: the point ``p``, the directions ``C``, the error ``e`` and the right-hand side ``b``.
A type registers its :class:`BatchedForm` here (:func:`register_batched_form`): the same
arithmetic as its ``evaluate`` and ``violation``, one numpy call over every period instead of
one per period, the same numbers bit for bit (``tests/test_loop_measures.py``). A type
without one (nor any base with one), or one overriding a method of that base's math
(:func:`constraints.math_methods.keeps_math`, ``violation`` too), is evaluated period by
period (:data:`PER_PERIOD`), the same numbers at Python's cost per call.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass
from typing import Any, Generic, Protocol, Sequence, TypeVar

import numpy as np
import pinocchio as pin

from constraints import Constraint, Hole
from constraints.math_methods import keeps_math
from constraints.norms import row_norms

from .constraint_measures import relative_rotations

C = TypeVar("C", bound=Constraint)
C_contra = TypeVar("C_contra", bound=Constraint, contravariant=True)


@dataclass(frozen=True)
class BatchedPoint:
    """:class:`constraints.base.ConstraintPoint` at ``N`` periods: ``p`` (N, 3), ``C``
    (N, k, 3), ``error`` (N, k), ``rhs`` (N, k), all in each period's ``F_a``."""

    p: np.ndarray
    C: np.ndarray
    error: np.ndarray
    rhs: np.ndarray


class BatchedForm(Protocol[C_contra]):
    """A constraint type's evaluation at ``N`` periods: ``constraints[i]`` (one type) at its
    link's placement ``rotations[i]`` (3 x 3), ``translations[i]`` (3,), world frame."""

    def evaluate(self, constraints: Sequence[C_contra], rotations: np.ndarray,
                 translations: np.ndarray) -> BatchedPoint:
        """``evaluate`` at every period (:class:`BatchedPoint`)."""

    def violation(self, constraints: Sequence[C_contra], rotations: np.ndarray,
                  translations: np.ndarray) -> np.ndarray:
        """``violation`` at every period (N,)."""


class PerPeriod(Generic[C]):
    """Any constraint type, one ``evaluate`` / ``violation`` call per period, stacked."""

    def evaluate(self, constraints: Sequence[C], rotations: np.ndarray,
                 translations: np.ndarray) -> BatchedPoint:
        points = [constraint.evaluate(pin.SE3(rotation, translation))
                  for constraint, rotation, translation
                  in zip(constraints, rotations, translations)]
        return BatchedPoint(np.array([point.p for point in points]),
                            np.array([point.C for point in points]),
                            np.array([point.error for point in points]),
                            np.array([point.rhs for point in points]))

    def violation(self, constraints: Sequence[C], rotations: np.ndarray,
                  translations: np.ndarray) -> np.ndarray:
        return np.array([constraint.violation(pin.SE3(rotation, translation))
                         for constraint, rotation, translation
                         in zip(constraints, rotations, translations)])


def transposed_times(rotations: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """``R_i^T v_i`` at every period (N, 3): the arithmetic of ``pin.SE3.actInv``'s rotation
    (Eigen's, compiled: each entry ``(R_0i v_0 + R_1i v_1) + R_2i v_2``), bit for bit:
    :func:`relative_rotations` with each vector as a column (a ``matmul`` would round by
    the BLAS kernel the CPU selects; with AVX-512 OpenBLAS fuses the products, Eigen does
    not)."""
    return relative_rotations(rotations, vectors[:, :, None])[:, :, 0]


def transposed(rotations: np.ndarray) -> np.ndarray:
    """Each ``R_i^T`` stored row-major, as numpy stores ``pin.SE3.rotation.T`` (a matrix
    times a vector rounds by its layout: the same bits need the same one)."""
    return np.ascontiguousarray(rotations.transpose(0, 2, 1))


def times(matrices: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """``M_i v_i`` at every period: each as ``M_i @ v_i``, bit for bit."""
    return np.matmul(matrices, vectors[..., None])[..., 0]


#: what :class:`HoleForm` reads of each hole (its geometry of that period)
ANCHOR, CENTER, LINK_AXIS, GAIN = (operator.attrgetter(name)
                                   for name in ("anchor", "center", "link_axis", "gain"))


def directions_of(hole: Hole) -> np.ndarray:
    """The hole's ``C`` (2 x 3), the same at every placement."""
    return hole.directions(IDENTITY)


#: a placement where a constraint's directions do not depend on it
IDENTITY = pin.SE3.Identity()


class HoleForm:
    """:meth:`Hole.evaluate` (docs/design.md section 3, the hole): with ``x = R^T (c - t)``
    the centre and ``f = R^T v_c`` its velocity in ``F_a``, ``p = (e . x) e``,
    ``error = -C x``, ``rhs = -K error + C f`` (``C f`` only where the hole moves)."""

    def evaluate(self, constraints: Sequence[Hole], rotations: np.ndarray,
                 translations: np.ndarray) -> BatchedPoint:
        anchors = np.array(list(map(ANCHOR, constraints)))
        axes = np.array(list(map(LINK_AXIS, constraints)))
        directions = np.array(list(map(directions_of, constraints)))
        gains = np.array(list(map(GAIN, constraints)))
        centers = transposed_times(rotations, anchors[:, :3] - translations)
        error = times(-directions, centers)
        rhs = -gains[:, None] * error
        moving: np.ndarray = np.any(anchors[:, 3:], axis=1)
        if moving.any():
            fed = rhs + times(directions, times(transposed(rotations), anchors[:, 3:]))
            rhs = np.where(moving[:, None], fed, rhs)
        along = (axes * centers).sum(axis=1)
        return BatchedPoint(along[:, None] * axes, directions, error, rhs)

    def violation(self, constraints: Sequence[Hole], rotations: np.ndarray,
                  translations: np.ndarray) -> np.ndarray:
        """``|error|`` (:meth:`Constraint.violation`), ``error = -C R^T (c - t)``."""
        centers = np.array(list(map(CENTER, constraints)))
        directions = np.array(list(map(directions_of, constraints)))
        error = times(-directions, transposed_times(rotations, centers - translations))
        return row_norms(error)


#: constraint type -> its batched form; a type not here (nor any of its bases): PER_PERIOD
BATCHED_FORMS: dict[type[Constraint], BatchedForm[Any]] = {}
PER_PERIOD: PerPeriod[Constraint] = PerPeriod()

#: what a batched form repeats beyond a constraint's evaluation: its ``violation``
BATCHED_MATH = ("violation",)


def register_batched_form(constraint_type: type[C], form: BatchedForm[C]) -> None:
    """Evaluate the constraints of ``constraint_type`` (or of a subclass without its own
    form or math) over many periods with ``form``."""
    BATCHED_FORMS[constraint_type] = form


def batched_form(constraint_type: type[Constraint]) -> BatchedForm[Any]:
    """The batched form of ``constraint_type``: its nearest registered base's, when the
    type keeps that base's math (:func:`~constraints.math_methods.keeps_math`) and
    :data:`BATCHED_MATH`; else :data:`PER_PERIOD`."""
    declaring = next((kind for kind in constraint_type.__mro__ if kind in BATCHED_FORMS), None)
    if declaring is None or not keeps_math(constraint_type, declaring, BATCHED_MATH):
        return PER_PERIOD
    return BATCHED_FORMS[declaring]


register_batched_form(Hole, HoleForm())
