"""Each built-in constraint type's placement on the page (``web.constraint_placement``)
and its ``place``; the registry's ``register``; the gain rule written once.

The reference for ``place`` is Pinocchio's forward kinematics at the configuration: the
point a declaration's distance names is ``distance`` m along the robot's link axis from
the link's frame, and the placed constraint holds there (an equality's error is zero, a
barrier's signed distance is its offset).
"""

from __future__ import annotations

import inspect

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from constraints import BUILTIN_TYPES, CONSTRAINT_TYPES, Barrier, Constraint, Hole, register
from web.constraint_placement import place, placement_of
from web.placement_fields import FIELD_TYPES, PlacementField

directions = st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(lambda v: np.linalg.norm(v) > 0.1)


@pytest.mark.parametrize("kind_type", BUILTIN_TYPES, ids=lambda t: t.kind)
def test_every_declared_field_is_a_keyword_of_place(kind_type):
    placement = placement_of(kind_type)
    keywords = list(inspect.signature(placement.place).parameters)
    assert keywords[:3] == [keywords[0], "robot", "q"]  # the type, then robot and q
    names = [field.name for field in placement.fields]
    assert len(set(names)) == len(names)
    assert set(names) <= set(keywords[3:])
    required = {name for name, parameter in inspect.signature(placement.place).parameters.items()
                if parameter.default is inspect.Parameter.empty} - set(keywords[:3])
    assert required <= set(names)  # a caller can always fill every required keyword
    assert [field.type for field in placement.fields].count("link") == 1
    assert all(field.type in FIELD_TYPES for field in placement.fields)


def test_a_subclass_is_placed_as_its_base_and_a_type_registered_nowhere_is_not():
    class LongHole(Hole):
        pass

    class Fixed(Constraint):
        kind = "fixed"
        label = "fixed point"

    assert placement_of(LongHole) is placement_of(Hole)
    assert placement_of(Barrier) is not placement_of(Barrier.__mro__[1])  # its own: an offset
    assert placement_of(Fixed) is None
    with pytest.raises(ValueError, match="a fixed point is not placed from the UI"):
        place(Fixed, None, None)


def test_a_field_of_an_unknown_type_or_link_choice_is_refused_naming_it():
    with pytest.raises(ValueError, match="placement field 'radius': unknown type 'length'"):
        PlacementField("radius", "length", "radius (m)")
    with pytest.raises(ValueError, match="placement field 'link': links must be"):
        PlacementField("link", "link", "arm", links="any")


def values_for(kind_type, robot, distance: float, normal, offset: float) -> dict:
    given = {"link": robot.constrained_link, "distance": distance, "normal": normal,
             "offset": offset}
    return {field.name: given[field.name] for field in placement_of(kind_type).fields
            if field.type != "link_point"}  # the constrained link has an axis: a distance


@settings(max_examples=40, deadline=None)
@given(kind_type=st.sampled_from(BUILTIN_TYPES), distance=st.floats(0.0, 0.2),
       normal=directions, offset=st.floats(0.0, 0.05),
       joints=st.lists(st.floats(-0.3, 0.3), min_size=8, max_size=8))
def test_place_puts_the_constraint_where_the_link_point_is_and_it_holds_there(
        sda10f, kind_type, distance, normal, offset, joints):
    model = sda10f.model
    q = np.clip(sda10f.q_home + np.resize(joints, model.nq),
                model.lowerPositionLimit, model.upperPositionLimit)
    unit = np.asarray(normal) / np.linalg.norm(normal)
    constraint = place(kind_type, sda10f, q, **values_for(kind_type, sda10f, distance, unit,
                                                           offset))
    assert type(constraint) is kind_type
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    link = data.oMf[model.getFrameId(sda10f.constrained_link)]
    point = link.act(distance * np.asarray(sda10f.link_axis))
    assert constraint.link == sda10f.constrained_link
    np.testing.assert_allclose(constraint.point_world(link), point, atol=1e-12)
    expected = point - offset * unit if kind_type is Barrier else point
    np.testing.assert_allclose(constraint.position, expected, atol=1e-12)
    assert constraint.violation(link) <= 1e-12
    if kind_type is Barrier:
        assert constraint.signed_distance(link) == pytest.approx(offset, abs=1e-12)


def test_a_barrier_placed_behind_its_point_is_refused(sda10f):
    with pytest.raises(ValueError, match="wrong side of the barrier"):
        place(Barrier, sda10f, sda10f.q_home, link=sda10f.constrained_link,
              normal=[0.0, 0.0, 1.0], distance=0.05, offset=-0.01)


def test_register_refuses_a_type_without_a_kind_or_a_kind_taken(monkeypatch):
    monkeypatch.setattr("constraints.registry.CONSTRAINT_TYPES", dict(CONSTRAINT_TYPES))

    class Nameless(Hole):
        kind = None

    class OtherHole(Hole):
        pass

    with pytest.raises(ValueError, match="Nameless needs a 'kind' name"):
        register(Nameless)
    with pytest.raises(ValueError, match="kind 'hole' is already Hole"):
        register(OtherHole)
    assert register(Hole) is Hole  # registering a type again changes nothing


@settings(max_examples=200, deadline=None)
@given(gain=st.floats(-10.0, 3000.0), rate=st.sampled_from([100.0, 1000.0, 2000.0]))
def test_the_gain_rule_is_k_dt_below_each_types_bound(gain, rate):
    dt = 1.0 / rate
    for kind_type, bound in ((Constraint, 2.0), (Hole, 2.0), (Barrier, 1.0)):
        assert kind_type.gain_rule.is_stable(gain, dt) == (0.0 <= gain * dt < bound)
        assert kind_type.gain_rule.bound(dt) == bound / dt
