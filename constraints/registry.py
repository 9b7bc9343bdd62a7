"""Every constraint type by its ``kind`` name: what :meth:`Constraint.from_dict` builds.

Adding a constraint type is one new module (a :class:`~constraints.base.Constraint`
subclass that sets ``kind``, ``dim``, ``position_attribute`` and the drawing attributes,
and keeps each constructor argument as an attribute of the same name) plus one line in
:data:`CONSTRAINT_TYPES`.
"""

from __future__ import annotations

from .barrier import Barrier
from .base import Constraint
from .hole import Hole
from .plane import Plane
from .point_lock import PointLock

#: ``kind -> type``, in the order error messages list them
CONSTRAINT_TYPES: dict[str, type[Constraint]] = {
    cls.kind: cls
    for cls in (
        Hole,
        Plane,
        Barrier,
        PointLock,
    )
}


def constraint_type(kind) -> type[Constraint]:
    """The constraint type named ``kind``; an unknown kind raises ``ValueError`` listing them."""
    if isinstance(kind, str) and kind in CONSTRAINT_TYPES:
        return CONSTRAINT_TYPES[kind]
    known = ", ".join(CONSTRAINT_TYPES)
    if kind is None:
        raise ValueError(f"a constraint needs a 'kind': one of {known}")
    raise ValueError(f"unknown constraint kind {kind!r}: {known}")
