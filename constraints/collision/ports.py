"""The constraint types whose geometry is a port: a place where the instrument passes
through the patient's body (a hole's trocar), so the instrument inside it is not kept away
from the obstacles around it (:meth:`CollisionAvoidance.set_ports`, docs/design.md 18).

A type is a port when it, or one of its bases, is registered here (:func:`register_port`).
"""

from __future__ import annotations

from ..base import Constraint
from ..hole import Hole

#: the types registered as ports (a subclass of one is a port too)
PORT_TYPES: set[type[Constraint]] = set()


def register_port(constraint_type: type[Constraint]) -> None:
    """Treat every constraint of ``constraint_type`` (and its subclasses) as a port."""
    PORT_TYPES.add(constraint_type)


def is_port(constraint: object) -> bool:
    """Whether ``constraint``'s geometry is a port the instrument passes through."""
    return any(kind in PORT_TYPES for kind in type(constraint).__mro__)


register_port(Hole)
