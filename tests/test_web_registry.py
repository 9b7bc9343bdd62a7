"""The UI is built from the registries: it names no constraint kind outside the files that
register the built-in kinds' pieces, and a kind defined here, registered with its
placement and drawing, is placed, drawn and offered by the UI without touching web/.

The kind: a point of the link kept on a world line (two equalities), written here with
its own directions and error, and the page's placement of it. The reference is
independent of the controllers: the point's world velocity by central finite differences
of Pinocchio's forward kinematics, and its distance from the line by forward kinematics.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import viser
from browser_helpers import free_port
from hypothesis import given, settings
from hypothesis import strategies as st

from constraints import CONSTRAINT_TYPES, Constraint
from constraints.base import DEFAULT_GAIN, link_point_at, perpendicular_basis
from constraints.validation import as_unit_vector, as_vector
from web.app import ControlThread, TeleopApp
from web.constraint_drawing import DRAWINGS, SHAPES, ConstraintDrawing
from web.constraint_placement import PLACEMENTS, ConstraintPlacement
from web.placement_fields import ALONG_LINK, ON_ARM, PlacementField
from web.ui import TeleopUI

WEB = Path(__file__).resolve().parent.parent / "web"
#: attributes of the lower layers' records that web reads and may not rename: their names
#: use the word for a one-sided constraint (read only, as ``record.<name>``)
LOWER_LAYER_FIELDS = {
    "active_barriers",  # controllers.SolveInfo: the one-sided rows held as equalities
    "barrier_penetration",  # teleop.loop.StepRecord: how far a point is behind one
}


class PointOnLine(Constraint):
    """Two equalities: the material point ``p`` of a link stays on the world line through
    ``line_point`` along the unit ``direction``.

    With ``W`` (2 x 3) two world directions perpendicular to the line, ``C = W R_a`` (rows
    in link coordinates), the error is ``W (x_c - line_point)`` and the feed-forward of a
    moving line ``W v``.
    """

    dim = 2
    kind = "point_on_line"
    position_attribute = "line_point"
    label = "point on line"

    def __init__(self, link: str, link_point, line_point, direction,
                 gain: float = DEFAULT_GAIN, velocity=(0.0, 0.0, 0.0)) -> None:
        super().__init__(link, gain)
        self.link_point = as_vector(link_point, 3, "link_point")
        self.line_point = as_vector(line_point, 3, "line_point")
        self.direction = as_unit_vector(direction, "line direction")
        self.velocity = as_vector(velocity, 3, "line velocity")
        self._across = perpendicular_basis(self.direction)

    def point(self, placement: pin.SE3) -> np.ndarray:
        return self.link_point

    def directions(self, placement: pin.SE3) -> np.ndarray:
        return self._across @ placement.rotation

    def error(self, placement: pin.SE3) -> np.ndarray:
        return self._across @ (placement.act(self.link_point) - self.line_point)

    def feed_forward(self, placement: pin.SE3) -> np.ndarray:
        return self._across @ self.velocity


def line_through_link_point(line_type: type[PointOnLine], robot, q, link: str,
                            distance: float, direction) -> PointOnLine:
    """The page's ``place`` of a PointOnLine: the line through the point ``distance`` m
    along ``link``'s axis, where it is at ``q``."""
    link, link_point, placement = link_point_at(robot, q, link, distance=distance)
    return line_type(link, link_point, placement.act(link_point), direction)


#: the page's placement of a PointOnLine: an arm, a distance and the line's direction
LINE_PLACEMENT = ConstraintPlacement(
    (ON_ARM, ALONG_LINK, PlacementField("direction", "direction", "direction (world)",
                                        default=(1.0, 0.0, 0.0), step=0.1,
                                        hint="the line's direction, world coordinates")),
    line_through_link_point)


@pytest.fixture()
def registered(monkeypatch):
    """PointOnLine in the registry for one test, placed by the page and drawn as a magenta
    point (all removed after it)."""
    monkeypatch.setitem(CONSTRAINT_TYPES, PointOnLine.kind, PointOnLine)
    monkeypatch.setitem(PLACEMENTS, PointOnLine, LINE_PLACEMENT)
    monkeypatch.setitem(DRAWINGS, PointOnLine, ConstraintDrawing("point", (200, 0, 200)))


# -- no kind named under web/ --------------------------------------------------------------


def kind_words() -> set[tuple[str, ...]]:
    """Every registered kind and label as a sequence of lower-case words."""
    words = set()
    for kind, kind_type in CONSTRAINT_TYPES.items():
        words.add(tuple(kind.lower().split("_")))
        words.add(tuple(kind_type.label.lower().split()))
    return words


def named_kind(text: str, words: set[tuple[str, ...]]) -> str | None:
    """The kind ``text`` names (an identifier split at ``_`` and capitals, or prose split
    into words; a plural counts), or None."""
    split = re.sub(r"([a-z0-9])([A-Z])", r"\1 \2", text).lower()
    tokens = [token for token in re.split(r"[^a-z0-9]+", split) if token]
    singular = [token[:-1] if token.endswith("s") else token for token in tokens]
    for word in words:
        for sequence in (tokens, singular):
            if any(tuple(sequence[i:i + len(word)]) == word
                   for i in range(len(sequence) - len(word) + 1)):
                return " ".join(word)
    return None


def kind_names_in(source: str, words: set[tuple[str, ...]]) -> list[tuple[int, str, str]]:
    """``(line, text, kind)`` for each string constant (docstrings included) and
    identifier of ``source`` that names a kind. Allowed: a drawing shape of
    :data:`web.constraint_drawing.SHAPES` as a dict key (the shape vocabulary, not a kind), and the
    :data:`LOWER_LAYER_FIELDS` read as attributes."""
    tree = ast.parse(source)
    shape_keys = {id(key) for node in ast.walk(tree) if isinstance(node, ast.Dict)
                  for key in node.keys
                  if isinstance(key, ast.Constant) and key.value in SHAPES}
    found = []
    for node in ast.walk(tree):
        texts = []
        if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and id(node) not in shape_keys:
            texts.append(node.value)
        if isinstance(node, ast.Name):
            texts.append(node.id)
        if isinstance(node, ast.Attribute) and not (node.attr in LOWER_LAYER_FIELDS
                                                    and isinstance(node.ctx, ast.Load)):
            texts.append(node.attr)
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            texts.append(node.name)
        if isinstance(node, ast.arg):
            texts.append(node.arg)
        if isinstance(node, ast.keyword) and node.arg:
            texts.append(node.arg)
        if isinstance(node, ast.alias):
            texts.append(node.asname or node.name)
        for text in texts:
            kind = named_kind(text, words)
            if kind is not None:
                found.append((getattr(node, "lineno", 0), text[:70], kind))
    return found


def test_the_scan_finds_a_kind_named_in_code_or_prose():
    words = kind_words()
    source = ('def add_hole(distance):\n'
              '    """Place a barrier."""\n'
              '    drawers = {"plane": distance, "ring": 1}\n'
              '    return kind == "plane" or kind == "point_lock"\n'
              'x = record.barrier_penetration\n'
              'record.barrier_penetration = 0\n'
              'PLANE_SIZE = 0.3\n')
    found = {(line, kind) for line, _, kind in kind_names_in(source, words)}
    assert found == {(1, "hole"), (2, "barrier"), (4, "plane"), (4, "point lock"),
                     (6, "barrier"), (7, "plane")}, found


#: the files under web/ that register the per-type pieces of the built-in kinds (their
#: drawing and placement): the places web names them
REGISTRATIONS = {WEB / "constraint_drawing.py", WEB / "constraint_placement.py"}


def test_no_file_under_web_names_a_constraint_kind():
    words = kind_words()
    assert {"hole", "plane", "barrier", "point lock"} <= {" ".join(w) for w in words}
    found = [f"{path.relative_to(WEB.parent)}:{line}: {text!r} names {kind!r}"
             for path in sorted(WEB.rglob("*.py")) if path not in REGISTRATIONS
             for line, text, kind in kind_names_in(path.read_text(), words)]
    assert not found, "\n".join(found)


def test_every_built_in_kind_registers_its_own_drawing():
    """Each kind has a drawing registered for its own type (not only its base's), with a
    shape the markers draw; a subclass without one draws as its nearest base."""
    for kind_type in CONSTRAINT_TYPES.values():
        assert DRAWINGS[kind_type].shape in SHAPES, kind_type
    assert len({DRAWINGS[kind_type].color for kind_type in CONSTRAINT_TYPES.values()}) == \
        len(CONSTRAINT_TYPES)


# -- a kind defined here, through the UI core ----------------------------------------------


def point_world(robot, q: np.ndarray, constraint: PointOnLine) -> np.ndarray:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(constraint.link)].act(constraint.link_point)


def lever_bound(robot, link: str, link_point: np.ndarray) -> float:
    """An upper bound (m), at every configuration, of the distance from any joint axis
    before ``link`` to the point: the sum of the chain's fixed offsets from joint to joint
    and to the point."""
    model = robot.model
    frame = model.frames[model.getFrameId(link)]
    total = float(np.linalg.norm(frame.placement.act(link_point)))
    joint = frame.parentJoint
    while joint > 0:
        total += float(np.linalg.norm(model.jointPlacements[joint].translation))
        joint = model.parents[joint]
    return total


def held_along_a_drag(robot, tmp_path, distance: float, direction, nudge) -> None:
    """Place a PointOnLine through the app, drag the target by ``nudge`` (m) and step 0.3 s:
    every step meets the constraint's rows at velocity level, and the point stays within
    the drift-feedback bound of the line."""
    app = TeleopApp(robot, record_dir=tmp_path / "sessions", scene_dir=tmp_path / "scenes")
    entry_id = app.constraints.add("point_on_line", distance=distance, direction=direction)
    assert entry_id == "point_on_line-1"
    line = app.constraints.entries[entry_id].constraint
    np.testing.assert_allclose(line.direction, np.asarray(direction) / np.linalg.norm(direction),
                               atol=1e-15)
    q0 = app.robots.loops["main"].q.copy()
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q0)
    link = data.oMf[robot.model.getFrameId(robot.constrained_link)]
    expected = link.act(distance * np.asarray(robot.link_axis))
    np.testing.assert_allclose(line.line_point, expected, atol=1e-12)
    across = perpendicular_basis(line.direction)

    app.console.nudge_target(nudge)
    dt, gain, h = app.robots.config.dt, app.robots.gain, 1e-6
    eps = np.finfo(float).eps
    lever = lever_bound(robot, line.link, line.link_point)
    error = np.zeros(2)  # where the point starts: on the line
    bound = 0.0
    for _ in range(int(0.3 * app.robots.config.rate)):
        loop = app.robots.loops["main"]
        q = loop.q.copy()
        app.step()
        info = loop.controller.info
        assert info.status.value not in ("failed", "constraint_degraded"), info.message
        qd = loop.last_qd
        np.testing.assert_allclose(loop.q, pin.integrate(robot.model, q, qd * dt), atol=1e-15)
        x = point_world(robot, q, line)
        velocity = (point_world(robot, pin.integrate(robot.model, q, h * qd), line)
                    - point_world(robot, pin.integrate(robot.model, q, -h * qd), line)) / (2 * h)
        error = across @ (x - line.line_point)
        # the rows at velocity level, W v = -K e: to the finite difference's rounding
        # (eps |x| / h) and the solve's (eps times the velocities, the conditioning kept
        # below 1e3 by the CJM's damping policy)
        rounding = 10 * eps * (1.0 + np.linalg.norm(x)) / h \
            + 1e3 * eps * (np.linalg.norm(velocity) + gain * np.linalg.norm(error))
        np.testing.assert_allclose(across @ velocity, -gain * error, rtol=0, atol=rounding)
        # one period moves the point by dt v plus a second-order remainder of at most
        # 0.5 lever (|qd|_1 dt)^2; drift feedback shrinks the error by (1 - K dt) a step
        remainder = 0.5 * lever * (np.abs(qd).sum() * dt) ** 2 + dt * rounding
        bound = (1.0 - gain * dt) * bound + remainder
    final = across @ (point_world(robot, app.robots.loops["main"].q, line) - line.line_point)
    assert np.linalg.norm(final) <= bound, (np.linalg.norm(final), bound)
    assert np.linalg.norm(app.robots.loops["main"].q - q0) > 1e-3  # the robot moved


def test_a_kind_registered_here_is_placed_and_held_through_the_ui_core(registered, sda10f,
                                                                        tmp_path):
    held_along_a_drag(sda10f, tmp_path, distance=0.08, direction=[0.0, 0.0, 2.0],
                      nudge=[0.0, 0.01, 0.0])


unit_vectors = st.tuples(*[st.floats(-1.0, 1.0)] * 3).filter(
    lambda v: np.linalg.norm(v) > 0.1)


@settings(max_examples=6, deadline=None)
@given(distance=st.floats(0.02, 0.15), direction=unit_vectors,
       nudge=st.tuples(*[st.floats(-0.01, 0.01)] * 3))
def test_a_registered_kind_holds_for_any_line_and_drag(sda10f, tmp_path_factory, distance,
                                                        direction, nudge):
    with pytest.MonkeyPatch.context() as patch:
        patch.setitem(CONSTRAINT_TYPES, PointOnLine.kind, PointOnLine)
        patch.setitem(PLACEMENTS, PointOnLine, LINE_PLACEMENT)
        held_along_a_drag(sda10f, tmp_path_factory.mktemp("line"), distance, direction,
                          nudge)


def test_a_registered_kind_refuses_bad_fields_naming_them(registered, sda10f, tmp_path):
    app = TeleopApp(sda10f, record_dir=tmp_path / "sessions", scene_dir=tmp_path / "scenes")
    with pytest.raises(ValueError, match="the point on line direction must be a non-zero"):
        app.constraints.add("point_on_line", direction=[0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="point on line distance must be between 0 and"):
        app.constraints.add("point_on_line", distance=5.0)
    with pytest.raises(ValueError, match="unknown field 'normal' for a point on line"):
        app.constraints.add("point_on_line", normal=[0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="unknown constraint kind 'line'"):
        app.constraints.add("line")
    assert not app.constraints.entries


def test_a_registered_kind_gets_its_inputs_and_is_drawn_from_its_geometry(registered, sda10f,
                                                                          tmp_path):
    app = TeleopApp(sda10f, record_dir=tmp_path / "sessions", scene_dir=tmp_path / "scenes")
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        ui = TeleopUI(server, app, ControlThread(app))
        inputs = ui.constraint_panel.inputs["point_on_line"]
        assert {name: handle.label for name, handle in inputs.items()} == {
            "link": "point on line arm", "distance": "point on line at (m)",
            "direction": "point on line direction (world)"}
        assert inputs["link"].value == sda10f.constrained_link
        assert inputs["distance"].value == ALONG_LINK.default
        inputs["distance"].value = 0.05
        inputs["direction"].value = (0.0, 1.0, 0.0)
        entry_id = ui.constraint_panel.add("point_on_line")  # what its "Add" button does
        line = app.constraints.entries[entry_id].constraint
        np.testing.assert_allclose(line.direction, [0.0, 1.0, 0.0])
        np.testing.assert_allclose(line.link_point, 0.05 * np.asarray(sda10f.link_axis),
                                   atol=1e-15)
        ui._draw(app.view.snapshot())
        markers = ui.constraint_markers.nodes[entry_id]
        assert markers["shape"].name == f"/constraints/{entry_id}/anchor"
        np.testing.assert_allclose(markers["shape"].position, line.line_point, atol=1e-6)
        assert "arrow" not in markers  # an equality: no allowed side
        assert tuple(ui.constraint_panel.menu.options) == (entry_id,)
    finally:
        server.stop()
