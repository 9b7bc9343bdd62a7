"""Every constraint type by its ``kind`` name: what :meth:`Constraint.from_dict` builds and
what the UI offers.

The table sits below every constraint module (it imports none of them), so
:mod:`constraints.base` reads it without an import circle; :mod:`constraints` fills it
with the built-in kinds. Adding a constraint type is one new module (a
:class:`~constraints.base.Constraint` subclass that sets ``kind``, ``dim``,
``position_attribute`` and ``label``, and keeps each constructor argument as an attribute
of the same name) plus :func:`register`; what another layer does with it (the page's
placement and drawing...) that layer registers.
"""

from __future__ import annotations

from typing import Any

#: ``kind -> type``, in the order error messages and the UI list them
CONSTRAINT_TYPES: dict[str, type] = {}


def register(constraint_type: type) -> type:
    """Add ``constraint_type`` to :data:`CONSTRAINT_TYPES` under its ``kind``; returns it.

    A type without a ``kind`` name, or a kind already taken by another type, raises
    ``ValueError``.
    """
    kind = getattr(constraint_type, "kind", None)
    if not isinstance(kind, str) or not kind.isidentifier():
        raise ValueError(f"{constraint_type.__name__} needs a 'kind' name, got {kind!r}")
    if CONSTRAINT_TYPES.get(kind, constraint_type) is not constraint_type:
        raise ValueError(f"kind {kind!r} is already {CONSTRAINT_TYPES[kind].__name__}")
    CONSTRAINT_TYPES[kind] = constraint_type
    return constraint_type


def constraint_type(kind) -> type[Any]:
    """The constraint type named ``kind``; an unknown kind raises ``ValueError`` listing them."""
    if isinstance(kind, str) and kind in CONSTRAINT_TYPES:
        return CONSTRAINT_TYPES[kind]
    known = ", ".join(CONSTRAINT_TYPES)
    if kind is None:
        raise ValueError(f"a constraint needs a 'kind': one of {known}")
    raise ValueError(f"unknown constraint kind {kind!r}: {known}")
