"""A constraint's fields are read-only and change by assignment only, each assignment
replacing its ``revision`` (constraints/revision.py): what the compiled CJM step and a
physics plant's compiled wall watch to read a constraint again."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from constraints import Barrier, Hole, Plane, PointLock


def samples() -> list:
    return [Hole("link", [0.4, 0.1, 0.9], link_axis=[0.0, 1.0, 0.0]),
            Plane("link", [0.0, 0.0, 0.1], [0.4, 0.1, 0.9], [0.0, 0.0, 1.0]),
            Barrier("link", [0.0, 0.0, 0.1], [0.4, 0.1, 0.9], [0.0, 0.0, 1.0]),
            PointLock("link", [0.0, 0.0, 0.1], [0.4, 0.1, 0.9])]


def arrays_of(constraint) -> dict[str, np.ndarray]:
    return {name: value for name, value in vars(constraint).items()
            if isinstance(value, np.ndarray)}


@pytest.mark.parametrize("constraint", samples(), ids=lambda c: c.kind)
def test_every_array_field_is_read_only_and_an_assignment_replaces_the_revision(constraint):
    assert arrays_of(constraint)
    for name, value in arrays_of(constraint).items():
        with pytest.raises(ValueError, match="read-only"):
            value[0] = 1.0
    revision = constraint.revision
    constraint.tissue_damping = 5.0  # any attribute, a number too
    assert constraint.revision is not revision and constraint.revision > revision


def test_an_assigned_array_is_copied_so_its_owner_cannot_change_the_constraint():
    owner = np.array([0.4, 0.1, 0.9, 0.0])
    lock = PointLock("link", [0.0, 0.0, 0.1], [0.0, 0.0, 0.0])
    lock.target = owner[:3]  # a view of a writeable array
    revision = lock.revision
    owner[:] = 7.0
    np.testing.assert_array_equal(lock.target, [0.4, 0.1, 0.9])
    assert lock.revision is revision


@pytest.mark.parametrize("duplicate", [copy.copy, copy.deepcopy,
                                       lambda c: pickle.loads(pickle.dumps(c))],
                         ids=["copy", "deepcopy", "pickle"])
@pytest.mark.parametrize("constraint", samples(), ids=lambda c: c.kind)
def test_a_copy_keeps_its_fields_read_only_with_a_revision_of_its_own(constraint, duplicate):
    twin = duplicate(constraint)
    assert twin.to_dict() == constraint.to_dict()
    assert twin.revision != constraint.revision
    for name, value in arrays_of(twin).items():
        np.testing.assert_array_equal(value, getattr(constraint, name))
        with pytest.raises(ValueError, match="read-only"):
            value[0] = 1.0
    revision = constraint.revision
    twin.move_to(twin.position + 0.1)
    assert constraint.revision is revision
    np.testing.assert_array_equal(twin.position, constraint.position + 0.1)
