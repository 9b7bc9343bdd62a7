"""What a constraint declares to the compiled CJM step (docs/design.md section 16).

A constraint type that the extension knows how to compute names its kind
(:attr:`CompiledForm.compiled_kind`: "hole", "plane", "point_lock"; a barrier is a plane
whose rows are inequalities) and gives its parameters as one read-only float64 array
(:meth:`CompiledForm.compiled_values`, the layout of each kind in
controllers/cjm/_step/terms.hpp). The array is replaced, never edited, whenever a field
it is made of is assigned, so the compiled step only has to see whether the array object
changed to read the constraint again. The fields themselves are stored read-only: they
change by assignment only (``move_to``, the setters, ``gain``).
"""

from __future__ import annotations

from functools import cache
from typing import ClassVar

import numpy as np

#: how far from 1 the norm of a declared axis or normal may be (as
#: :func:`constraints.validation.as_unit_vector` accepts it); the compiled step checks it
UNIT_TOLERANCE = 1e-6


class CompiledForm:
    """The declaration of :class:`constraints.base.Constraint` to the compiled step."""

    #: the compiled CJM step's name of this type's terms, or None: the compiled step has
    #: Python write them (a user's own type)
    compiled_kind: ClassVar[str | None] = None
    #: the attributes :meth:`compiled_values` reads: assigning one declares anew (an
    #: array is stored as a read-only copy)
    compiled_fields: ClassVar[tuple[str, ...]] = ()
    #: the methods whose math the compiled kind repeats: a subclass overriding one of
    #: them declares no compiled form (its own math runs in Python)
    compiled_math: ClassVar[tuple[str, ...]] = (
        "point", "directions", "free_directions", "error", "feed_forward", "evaluate")
    #: the declared parameters (read-only, replaced whenever a field changes), set once
    #: every field of :attr:`compiled_fields` is
    compiled_parameters: np.ndarray

    def compiled_form(self) -> tuple[str, np.ndarray] | None:
        """``(kind, parameters)``: the compiled CJM step computes this constraint's terms
        from them in C++, reading the parameters again whenever the array is replaced;
        None when the type declares none (Python then writes its terms)."""
        # (mypy takes the class's __hash__ for an unbound method: not Hashable)
        if not declares_compiled_form(type(self)):  # type: ignore[arg-type]
            return None
        return self.compiled_kind, self.compiled_parameters

    def compiled_values(self) -> np.ndarray:
        """The parameters of :attr:`compiled_kind`, from the fields (a new float array)."""
        raise NotImplementedError(f"{type(self).__name__} declares no compiled form")

    def __setattr__(self, name: str, value: object) -> None:
        """Assigning a field of :attr:`compiled_fields` declares the parameters anew."""
        if name in self.compiled_fields:
            if isinstance(value, np.ndarray):
                frozen = value.copy()
                frozen.flags.writeable = False
                value = frozen
            object.__setattr__(self, name, value)
            self._declare()
        else:
            object.__setattr__(self, name, value)

    def _declare(self) -> None:
        """Replace :attr:`compiled_parameters` once every field is set."""
        if all(name in self.__dict__ for name in self.compiled_fields):
            parameters = self.compiled_values()
            parameters.flags.writeable = False
            object.__setattr__(self, "compiled_parameters", parameters)

    def __setstate__(self, state: dict) -> None:
        """A copy (``copy.deepcopy``, ``pickle``) keeps its fields read-only and declares
        its parameters anew."""
        for name, value in state.items():
            if name != "compiled_parameters":
                CompiledForm.__setattr__(self, name, value)


@cache
def declares_compiled_form(constraint_type: type[CompiledForm]) -> bool:
    """Whether ``constraint_type`` has a compiled kind whose math it keeps: the class
    that set :attr:`CompiledForm.compiled_kind` defines every method of
    :attr:`CompiledForm.compiled_math` the type uses (a subclass with its own geometry
    gets no compiled form it does not compute)."""
    if constraint_type.compiled_kind is None:
        return False
    declaring = next(cls for cls in constraint_type.__mro__ if "compiled_kind" in cls.__dict__)
    return all(getattr(constraint_type, name) is getattr(declaring, name)
               for name in constraint_type.compiled_math)
