"""A constraint's fields are read-only and change by assignment only; every assignment
replaces the constraint's ``revision`` (docs/design.md section 16).

A reader that keeps a constraint and copies numbers out of it (the compiled CJM step,
``controllers/cjm/compiled_forms.py``; a physics plant's compiled wall,
``teleop/plants/walls.py``) sees whether it changed since it last read by comparing
``revision`` with ``is``: no method call, no comparison of values. An array assigned is
stored as a read-only copy (one already read-only that owns its data, as a copy's, is
kept), so no field changes in place and a shallow copy of a constraint keeps its geometry.
"""

from __future__ import annotations

import itertools

import numpy as np

#: the revisions handed out, one integer per assignment across every constraint
REVISIONS = itertools.count()


class ReadOnlyFields:
    """Read-only array fields and a :attr:`revision` replaced by every assignment."""

    #: replaced whenever an attribute is assigned: compare it with ``is``
    revision: int

    def __setattr__(self, name: str, value: object) -> None:
        """Store ``value`` (an array as a read-only copy) and replace :attr:`revision`."""
        if isinstance(value, np.ndarray) and (value.flags.writeable or not value.flags.owndata):
            frozen = value.copy()
            frozen.flags.writeable = False
            value = frozen
        object.__setattr__(self, name, value)
        object.__setattr__(self, "revision", next(REVISIONS))

    def __setstate__(self, state: dict) -> None:
        """A copy (``copy.copy``, ``copy.deepcopy``, ``pickle``) keeps its fields read-only
        and gets a revision of its own."""
        for name, value in state.items():
            if name != "revision":
                ReadOnlyFields.__setattr__(self, name, value)
