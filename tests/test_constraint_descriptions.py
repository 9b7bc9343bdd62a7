"""Constraints describe themselves: kind, to_dict / from_dict, position / move_to; and the
page draws each from its type's registered drawing (web.constraint_drawing).

No layer above ``constraints`` branches on a constraint's type; these tests hold every
registered kind to the same contract, so a new kind that does not fill it in fails here.
"""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from browser_helpers import free_port
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from strategies import unit3, vec3

from constraints import (
    CONSTRAINT_TYPES,
    Barrier,
    Constraint,
    Hole,
    Plane,
    PointLock,
)
from constraints.kinematics import frame_placement
from teleop import load_robot
from web.constraint_drawing import ConstraintGeometry, constraint_geometry, drawing_of

ROBOT = load_robot("sda10f")  # hypothesis tests cannot take function-scoped fixtures
LINKS = (ROBOT.constrained_link, ROBOT.ee_frame)
gains = st.floats(0.0, 500.0)
velocities = st.one_of(st.just(np.zeros(3)), vec3)

#: a strategy of random geometry for every kind: a new kind must add one here
BUILDERS = {
    "hole": lambda link: st.builds(Hole, st.just(link), vec3, link_axis=unit3, gain=gains,
                                   velocity=velocities),
    "plane": lambda link: st.builds(Plane, st.just(link), vec3, vec3, unit3, gain=gains,
                                    velocity=velocities),
    "barrier": lambda link: st.builds(Barrier, st.just(link), vec3, vec3, unit3, gain=gains,
                                      velocity=velocities),
    "point_lock": lambda link: st.builds(PointLock, st.just(link), vec3, vec3, gain=gains,
                                         velocity=velocities),
}

#: the fields that session files written before ``to_dict`` existed hold, per kind
SESSION_FIELDS = {
    "hole": {"kind", "link", "center", "link_axis", "gain"},
    "plane": {"kind", "link", "link_point", "plane_point", "normal", "gain"},
    "barrier": {"kind", "link", "link_point", "plane_point", "normal", "gain"},
    "point_lock": {"kind", "link", "link_point", "target", "gain"},
}

LINK = ROBOT.constrained_link  # "arm_link_5_r"
GOOD = {
    "hole": {"kind": "hole", "link": LINK, "center": [0.5, 0.2, 0.1]},
    "plane": {"kind": "plane", "link": LINK, "link_point": [0, 0, 0], "plane_point": [0, 0, 0],
              "normal": [0, 0, 1]},
    "barrier": {"kind": "barrier", "link": LINK, "link_point": [0, 0, 0.1],
                "plane_point": [0.5, 0.2, 0.0], "normal": [0, 0, 1]},
    "point_lock": {"kind": "point_lock", "link": LINK, "link_point": [0, 0, 0.1],
                   "target": [0.5, 0.2, 0.1]},
}


def sample(kind: str) -> Constraint:
    """A fixed constraint of ``kind`` (at rest)."""
    return Constraint.from_dict(GOOD[kind])


@st.composite
def constraints(draw, kind: str | None = None) -> Constraint:
    kind = draw(st.sampled_from(sorted(BUILDERS))) if kind is None else kind
    return draw(BUILDERS[kind](draw(st.sampled_from(LINKS))))


@st.composite
def configurations(draw) -> np.ndarray:
    model = ROBOT.model
    unit = draw(arrays(float, model.nq, elements=st.floats(0.0, 1.0)))
    return model.lowerPositionLimit + unit * (model.upperPositionLimit - model.lowerPositionLimit)


def rows_at(constraint: Constraint, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    data = ROBOT.model.createData()
    pin.computeJointJacobians(ROBOT.model, data, q)
    pin.updateFramePlacements(ROBOT.model, data)
    A, b = constraint.rows(ROBOT.model, data)
    return A.copy(), b.copy()


def placement_at(constraint: Constraint, q: np.ndarray) -> pin.SE3:
    return frame_placement(ROBOT.model, q, constraint.link)


def test_every_registered_kind_is_covered_and_named():
    assert set(BUILDERS) == set(CONSTRAINT_TYPES) == set(SESSION_FIELDS)
    for kind, cls in CONSTRAINT_TYPES.items():
        assert cls.kind == kind
        assert cls.label


# ----------------------------------------------------------------------- to_dict / from_dict


@settings(max_examples=200, deadline=None)
@given(constraint=constraints(), q=configurations())
def test_round_trip_through_json_gives_the_same_rows(constraint, q):
    data = constraint.to_dict()
    assert data["kind"] == constraint.kind
    rebuilt = Constraint.from_dict(json.loads(json.dumps(data)))  # JSON-ready, exactly
    assert type(rebuilt) is type(constraint)
    assert rebuilt.to_dict().keys() == data.keys()
    A, b = rows_at(constraint, q)
    A_rebuilt, b_rebuilt = rows_at(rebuilt, q)
    np.testing.assert_allclose(A_rebuilt, A, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b_rebuilt, b, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(rebuilt.position, constraint.position)
    np.testing.assert_array_equal(rebuilt.velocity, constraint.velocity)


@pytest.mark.parametrize("kind", sorted(BUILDERS))
def test_a_constraint_at_rest_writes_the_session_file_fields(kind):
    constraint = sample(kind)
    assert set(constraint.to_dict()) == SESSION_FIELDS[kind]
    constraint.move_to(constraint.position, velocity=[0.0, 0.01, 0.0])
    assert set(constraint.to_dict()) == SESSION_FIELDS[kind] | {"velocity"}


def test_session_file_dicts_load_as_before():
    """Dicts as the earlier ``constraint_to_dict`` wrote them (tests/test_session_cli.py)."""
    link = ROBOT.constrained_link
    hole = Constraint.from_dict({"kind": "hole", "link": link, "center": [0.5, 0.2, 0.1],
                                 "link_axis": [0.0, 0.0, -1.0], "gain": 100.0})
    barrier = Constraint.from_dict({"kind": "barrier", "link": link,
                                    "link_point": [0.0, 0.0, -0.05], "plane_point": [0, 0, 0],
                                    "normal": [0.0, 0.0, 1.0], "gain": 50.0})
    lock = Constraint.from_dict({"kind": "point_lock", "link": link,
                                 "link_point": [0.0, 0.0, 0.1], "target": [0.5, 0.2, 0.1],
                                 "gain": 100.0})
    assert type(hole) is Hole and hole.center.tolist() == [0.5, 0.2, 0.1]
    assert type(barrier) is Barrier and not barrier.is_equality and barrier.gain == 50.0
    assert type(lock) is PointLock and lock.target.tolist() == [0.5, 0.2, 0.1]
    assert Plane.from_dict(barrier.to_dict()).kind == "barrier"  # a Barrier is a Plane


@pytest.mark.parametrize("data, field", [
    ([1, 2, 3], "constraint must be an object"),
    ({"link": LINK, "center": [0, 0, 0]}, "'kind'"),
    ({**GOOD["hole"], "kind": "wormhole"}, "unknown constraint kind 'wormhole'"),
    ({**GOOD["hole"], "kind": 3}, "unknown constraint kind 3"),
    ({"kind": "hole", "link": LINK}, "'center'"),
    ({"kind": "plane", "link": LINK}, "'link_point', 'plane_point', 'normal'"),
    ({**GOOD["hole"], "radius": 0.01}, "unknown field 'radius'"),
    ({**GOOD["hole"], "center": [0, 0]}, r"center must have shape \(3,\)"),
    ({**GOOD["hole"], "center": "here"}, "center must be an array"),
    ({**GOOD["hole"], "link_axis": [0, 0, 2]}, "link_axis must be a unit vector"),
    ({**GOOD["hole"], "link": ""}, "link must be a non-empty"),
    ({**GOOD["hole"], "link": None}, "link must be a non-empty"),
    ({**GOOD["hole"], "gain": -1.0}, "gain must be >= 0"),
    ({**GOOD["hole"], "gain": "fast"}, "gain must be a number"),
    ({**GOOD["hole"], "velocity": [0, float("nan"), 0]}, "velocity must be finite"),
    ({**GOOD["plane"], "normal": [0, 0, 0]}, "normal must be a unit vector"),
    ({**GOOD["plane"], "plane_point": None}, "plane_point must be an array"),
    ({**GOOD["point_lock"], "target": [0, 0, 0, 0]}, r"target must have shape \(3,\)"),
    ({**GOOD["point_lock"], "link_point": [[0, 0, 0]]}, "link_point must have shape"),
])
def test_bad_dicts_raise_value_errors_naming_the_field(data, field):
    with pytest.raises(ValueError, match=field):
        Constraint.from_dict(data)


def test_from_dict_of_a_subclass_refuses_another_kind():
    with pytest.raises(ValueError, match="kind 'plane' is not a Hole"):
        Hole.from_dict(GOOD["plane"])
    for data in GOOD.values():  # and the good ones are good
        assert Constraint.from_dict(data).kind == data["kind"]


# ----------------------------------------------------------------------------- move_to


@settings(max_examples=100, deadline=None)
@given(constraint=constraints(), q=configurations(), position=vec3, velocity=vec3)
def test_move_to_moves_the_reference_point_and_feeds_the_velocity_forward(
        constraint, q, position, velocity):
    constraint.move_to(position)
    np.testing.assert_array_equal(constraint.position, position)
    np.testing.assert_array_equal(constraint.velocity, np.zeros(3))
    A_static, b_static = rows_at(constraint, q)
    # the same geometry built afresh at the new place gives the same rows
    fresh = Constraint.from_dict({**constraint.to_dict(), constraint.position_attribute: position})
    np.testing.assert_allclose(rows_at(fresh, q)[1], b_static, rtol=0, atol=1e-12)

    constraint.move_to(position, velocity)
    A_moving, b_moving = rows_at(constraint, q)
    placement = placement_at(constraint, q)
    C = constraint.evaluate(placement).C  # F_a coordinates, as the world velocity must be
    np.testing.assert_array_equal(A_moving, A_static)
    np.testing.assert_allclose(b_moving - b_static, C @ (placement.rotation.T @ velocity),
                               rtol=0, atol=1e-12)

    constraint.move_to(position)  # at rest again: no feed-forward left over
    np.testing.assert_allclose(rows_at(constraint, q)[1], b_static, rtol=0, atol=1e-12)


@pytest.mark.parametrize("kind, name", [("hole", "center"), ("plane", "plane_point"),
                                        ("barrier", "plane_point"), ("point_lock", "target")])
def test_move_to_keeps_each_kinds_own_keyword(kind, name):
    constraint = sample(kind)
    assert constraint.position_attribute == name
    constraint.move_to(**{name: [0.1, 0.2, 0.3]}, velocity=[0.0, 0.0, 0.01])
    assert getattr(constraint, name).tolist() == [0.1, 0.2, 0.3]
    assert constraint.velocity.tolist() == [0.0, 0.0, 0.01]
    constraint.move_to(position=[0.3, 0.2, 0.1])
    assert constraint.position.tolist() == [0.3, 0.2, 0.1]
    assert not constraint.velocity.any()
    wrong = "target" if name != "target" else "center"
    with pytest.raises(TypeError, match=name):
        constraint.move_to(**{wrong: [0.0, 0.0, 0.0]})
    with pytest.raises(ValueError, match=f"{name} must have shape"):
        constraint.move_to([0.0, 0.0])
    assert constraint.position.tolist() == [0.3, 0.2, 0.1]  # a refused move changes nothing


def test_position_is_a_copy():
    hole = sample("hole")
    hole.position[:] = 7.0
    assert not np.all(hole.center == 7.0)


# ----------------------------------------------------------------------------- geometry


@settings(max_examples=200, deadline=None)
@given(constraint=constraints(), q=configurations())
def test_geometry_is_in_the_world_and_its_error_leads_back_to_satisfaction(constraint, q):
    placement = placement_at(constraint, q)
    geometry = constraint_geometry(constraint, placement)
    assert isinstance(geometry, ConstraintGeometry)
    drawing = drawing_of(constraint)
    assert (geometry.kind, geometry.shape, geometry.color, geometry.label) == (
        constraint.kind, drawing.shape, drawing.color, constraint.label)
    np.testing.assert_array_equal(geometry.anchor, constraint.position)
    np.testing.assert_allclose(geometry.point, placement.act(constraint.point(placement)),
                               atol=1e-12)
    assert geometry.error.shape == (3,)
    assert np.linalg.norm(geometry.error) == pytest.approx(constraint.violation(placement),
                                                          abs=1e-12)
    if geometry.axis is not None:
        assert np.linalg.norm(geometry.axis) == pytest.approx(1.0)
    # the error is the world form of the constraint's own error: C R^T e_world = error
    if constraint.is_equality:
        state = constraint.evaluate(placement)
        np.testing.assert_allclose(state.C @ (placement.rotation.T @ geometry.error),
                                   state.error, atol=1e-12)


def test_a_satisfied_barrier_has_a_zero_error_vector():
    q = ROBOT.q_home
    placement = frame_placement(ROBOT.model, q, ROBOT.constrained_link)
    barrier = Barrier.through_link_point(ROBOT, q, normal=[0.0, 0.0, 1.0], distance=0.08)
    barrier.move_to(barrier.position - [0.0, 0.0, 0.02])  # 2 cm below the point: allowed side
    assert barrier.signed_distance(placement) == pytest.approx(0.02)
    geometry = constraint_geometry(barrier, placement)
    assert geometry.error.tolist() == [0.0, 0.0, 0.0]
    assert barrier.violation(placement) == 0.0
    barrier.move_to(barrier.position + [0.0, 0.0, 0.05])  # now 3 cm behind it
    geometry = constraint_geometry(barrier, placement)
    np.testing.assert_allclose(geometry.error, [0.0, 0.0, -0.03], atol=1e-12)
    assert barrier.violation(placement) == pytest.approx(0.03)
    # back along the error the point is on the plane
    assert barrier.normal @ (geometry.point - geometry.error - barrier.plane_point) == \
        pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("kind", ["hole", "point_lock"])
def test_the_error_of_a_hole_or_a_lock_leads_to_its_anchor(kind):
    constraint = sample(kind)
    placement = frame_placement(ROBOT.model, ROBOT.q_home, constraint.link)
    geometry = constraint_geometry(constraint, placement)
    np.testing.assert_allclose(geometry.point - geometry.error, geometry.anchor, atol=1e-12)


# ------------------------------------------------------------------ through the web app


@pytest.fixture()
def app(tmp_path):
    from web.app import TeleopApp

    return TeleopApp(ROBOT, controller="cjm", record_dir=tmp_path)


def run(app, seconds):
    for _ in range(int(seconds * app.robots.config.rate)):
        app.step()


def test_a_point_lock_is_added_moved_and_recorded_through_the_app(app):
    from teleop.experiments.compare import run_plan
    from teleop.experiments.sessions import load_session, session_plan

    path = app.start_recording()
    lock_id = app.constraints.add("point_lock", distance=0.08)
    entry = app.constraints.entries[lock_id]
    assert lock_id.startswith("point_lock-") and entry.kind == "point_lock"
    start = entry.position
    snapshot = app.view.snapshot()["constraints"]
    assert [e["geometry"].shape for e in snapshot] == ["point"]
    np.testing.assert_allclose(snapshot[0]["geometry"].anchor, start)
    app.constraints.move(lock_id, start + [0.0, 0.0, 0.003])
    run(app, 0.5)
    np.testing.assert_allclose(entry.position, start + [0.0, 0.0, 0.003], atol=1e-5)
    record = app.robots.last_records["main"]
    assert not record.failed and record.constraint_error < 1e-5
    geometry = app.view.snapshot()["constraints"][0]["geometry"]
    assert np.linalg.norm(geometry.error) < 1e-5
    app.robots.set_gain(50.0)
    assert entry.constraint.gain == 50.0
    app.constraints.remove(lock_id)
    app.stop_recording()
    session = load_session(path)
    added = [e for e in session.events if e["type"] == "add"]
    assert added[0]["constraint"]["kind"] == "point_lock"
    assert any(e["type"] == "move" for e in session.events)
    assert run_plan(session_plan(session), "cjm").metrics()["failed_steps"] == 0


def test_a_gain_a_barrier_cannot_take_is_refused_and_changes_nothing(app):
    app.robots.set_gain(150.0)
    barrier_id = app.constraints.add("barrier", distance=0.05, normal=[0.0, 0.0, 1.0], offset=0.01)
    assert app.constraints.entries[barrier_id].constraint.gain == 150.0  # no special case for barriers
    app.robots.set_gain(100.0)
    assert app.constraints.entries[barrier_id].constraint.gain == 100.0
    hole_id = app.constraints.add("hole", distance=0.08)
    with pytest.raises(ValueError, match="Barrier gain 1500"):
        app.robots.set_gain(1500.0)  # K dt = 1.5: stable drift feedback, a barrier could be crossed
    assert app.robots.gain == 100.0
    for entry_id in (hole_id, barrier_id):
        assert app.constraints.entries[entry_id].constraint.gain == 100.0
    run(app, 0.02)
    assert not app.robots.last_records["main"].failed


def test_a_constraint_the_controllers_refuse_is_not_placed(app):
    with pytest.raises(ValueError, match="unknown link"):
        app.constraints.add(PointLock("no_such_link", [0, 0, 0], [0, 0, 0]))
    assert not app.constraints.entries
    run(app, 0.01)
    with pytest.raises(ValueError, match="expected a constraint"):
        app.constraints.add({"kind": "hole"})


def test_the_ui_draws_every_kind_from_its_geometry(app):
    """The viser scene (no browser): one marker set per constraint, shaped by its geometry."""
    import viser

    from web.app import ControlThread
    from web.ui import TeleopUI

    ids = {"hole": app.constraints.add("hole", distance=0.08),
           "plane": app.constraints.add("plane", distance=0.08, normal=[0.0, 1.0, 0.0]),
           "barrier": app.constraints.add("barrier", distance=0.05, normal=[0.0, 0.0, 1.0],
                                         offset=0.01),
           "point_lock": app.constraints.add("point_lock", distance=0.04)}
    app.constraints.move(ids["point_lock"], app.constraints.entries[ids["point_lock"]].position + 0.01)
    run(app, 0.01)  # the lock lags its goal: a visible error vector
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        ui = TeleopUI(server, app, ControlThread(app))
        ui._draw(app.view.snapshot())
        names = {kind: ui.constraint_markers.nodes[entry_id]["shape"].name for kind, entry_id in ids.items()}
        assert names == {"hole": f"/constraints/{ids['hole']}/ring",
                         "plane": f"/constraints/{ids['plane']}/plane",
                         "barrier": f"/constraints/{ids['barrier']}/plane",
                         "point_lock": f"/constraints/{ids['point_lock']}/anchor"}
        assert not ui.constraint_markers.nodes[ids["barrier"]]["error"].visible  # allowed side: no 1 m line
        assert ui.constraint_markers.nodes[ids["point_lock"]]["error"].visible
        app.constraints.remove(ids["hole"])
        ui._draw(app.view.snapshot())
        assert ids["hole"] not in ui.constraint_markers.nodes
    finally:
        server.stop()


@given(a=vec3, b=vec3)
def test_the_cross_product_is_numpys_bit_for_bit(a, b):
    """``constraints.base.cross`` (a plane's or lock's basis every step) is ``np.cross``."""
    from constraints.base import cross, perpendicular_basis

    np.testing.assert_array_equal(cross(np.asarray(a), np.asarray(b)), np.cross(a, b))
    axis = np.asarray(a) / max(np.linalg.norm(a), 1e-300)
    if abs(np.linalg.norm(axis) - 1.0) < 1e-12:
        basis = perpendicular_basis(axis)
        np.testing.assert_allclose(basis @ basis.T, np.eye(2), atol=1e-12)
        np.testing.assert_allclose(basis @ axis, 0.0, atol=1e-12)
        np.testing.assert_allclose(np.cross(basis[0], basis[1]), axis, atol=1e-12)
