"""Collision avoidance in the browser session's core (docs/design.md section 18): obstacles
added, moved and removed through :class:`web.app.TeleopApp`, scenes that keep them, the
settings, and what the view shows (the minimum distance, the highlighted pairs and their
witness segments) against :class:`constraints.collision.CollisionAvoidance` rows computed
here, independently, at the configuration the controller computed its own from.
"""

from __future__ import annotations

import dataclasses
import json
import math
import subprocess
import sys
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import pytest
import viser
from browser_helpers import free_port
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from constraints.collision import CollisionAvoidance
from constraints.collision.geometry import shape_distance
from teleop.experiments.scenarios import load_scenario
from teleop.loop.moving_geometry import MAX_GEOMETRY_SPEED
from teleop.plants.choice import PlantChoice
from web.app import ControlThread, TeleopApp
from web.app.collisions import FRONT_GAP
from web.ui import COLLISION_PLOTS, PLOTS, TeleopUI, distance_color, node_name, plots_of
from web.ui.collision_view import FAR_COLOR, NEAR_COLOR
from web.ui.status_view import collision_words

DATA = Path(__file__).parent / "data"
#: witness points and distances of two computations of the same pair at the same q
SAME = 1e-12


@pytest.fixture()
def app(sda10f, tmp_path):
    return TeleopApp(sda10f, record_dir=tmp_path / "sessions", scene_dir=tmp_path / "scenes")


@pytest.fixture()
def dual_app(dual, tmp_path):
    return TeleopApp(dual, record_dir=tmp_path / "sessions", scene_dir=tmp_path / "scenes")


def run(app, seconds: float) -> None:
    for _ in range(int(round(seconds * app.robots.config.rate))):
        app.step()


def run_to_measure(app, which: str = "main") -> np.ndarray:
    """Step until the next measured (history) tick; robot ``which``'s configuration its
    command was computed from on that tick (the kinematic plant senses the true q), where
    its controller computed the rows the view reads."""
    record = app.robots.last_records[which]
    while app.robots.last_records[which] is record:
        q = app.robots.loops[which].q.copy()
        app.step()
    return q


def tip(app, ee: int = 0) -> pin.SE3:
    """EE ``ee``'s world pose by forward kinematics of the main robot's q."""
    robot = app.robot
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, app.robots.loops["main"].q)
    return data.oMf[robot.ee_frame_ids[ee]].copy()


def independent_rows(app, which: str = "main", q: np.ndarray | None = None):
    """The rows of a new avoidance with the app's settings and copies of its obstacles, at
    ``q`` (default: robot ``which``'s q now), on a fresh ``pin.Data``."""
    settings = app.collisions.avoidance.to_dict()
    avoidance = CollisionAvoidance.from_dict(app.robot, settings)
    avoidance.set_ports([entry.constraint for entry in app.constraints.entries.values()])
    model = app.robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, app.robots.loops[which].q if q is None else q)
    return avoidance.rows(model, data)


# -- adding, moving and removing ---------------------------------------------------------------

@settings(max_examples=15, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kind=st.sampled_from(["sphere", "box", "capsule"]),
       radius=st.floats(0.01, 0.1), length=st.floats(0.0, 0.2),
       edges=st.lists(st.floats(0.01, 0.2), min_size=3, max_size=3),
       turn=st.lists(st.floats(-np.pi, np.pi), min_size=3, max_size=3))
def test_an_obstacle_goes_its_gap_in_front_of_the_tip(app, kind, radius, length, edges, turn):
    """The nearest point of a new obstacle along the tool's z axis is FRONT_GAP from the
    tip: the obstacle touches the half-space of the points less than FRONT_GAP ahead, and
    is 1 mm from the one less than FRONT_GAP - 1 mm ahead (coal's distance)."""
    norm = float(np.linalg.norm(turn))
    axis = np.asarray(turn) / norm if norm > 1e-3 else np.array([0.0, 0.0, 1.0])
    fields = {"sphere": {"radius": radius}, "capsule": {"radius": radius, "length": length,
                                                        "axis": axis},
              "box": {"size": edges, "rpy": turn}}[kind]
    entry_id = app.collisions.add(kind, **fields)
    obstacle = app.collisions.obstacles[entry_id].obstacle
    pose = tip(app)
    approach = pose.rotation[:, 2]
    for gap, expected in ((FRONT_GAP, 0.0), (FRONT_GAP - 1e-3, 1e-3)):
        behind = coal.Halfspace(approach, float(approach @ pose.translation) + gap)
        distance = shape_distance(obstacle.shape(), obstacle.pose(), behind, pin.SE3.Identity())
        assert distance == pytest.approx(expected, abs=1e-9)
    app.collisions.remove(entry_id)


def test_a_half_space_is_its_gap_from_the_tip_facing_it(app):
    entry_id = app.collisions.add("halfspace", normal=(0.0, 0.0, 1.0))
    obstacle = app.collisions.obstacles[entry_id].obstacle
    distance = shape_distance(coal.Sphere(1e-9), pin.SE3(np.eye(3), tip(app).translation),
                              obstacle.shape(), obstacle.pose())
    assert distance == pytest.approx(FRONT_GAP, abs=1e-9)


def test_obstacles_are_added_moved_with_feed_forward_and_removed(app):
    first = app.collisions.add("sphere", radius=0.03)
    second = app.collisions.add("box", center=tip(app).translation + [0.0, 0.0, -0.3],
                              size=(0.1, 0.2, 0.05))
    assert (first, second) == ("sphere-1", "box-2")
    assert [o.name for o in app.collisions.avoidance.obstacles] == [first, second]
    assert {pair[1] for pair in app.collisions.avoidance.pairs} == {first, second}
    # every controller holds the session's avoidance
    assert app.robots.loops["main"].controller.collisions is app.collisions.avoidance

    start = app.collisions.obstacles[first].obstacle.position
    goal = start + np.array([0.0, 0.0, 0.01])
    app.collisions.move(first, goal)
    speeds, positions = [], []
    for _ in range(200):
        app.step()
        obstacle = app.collisions.obstacles[first].obstacle
        speeds.append(float(np.linalg.norm(obstacle.velocity)))
        positions.append(obstacle.position)
    # it glides (no jump), at most the geometry speed cap, along the move
    steps = np.linalg.norm(np.diff([start, *positions], axis=0), axis=1)
    assert max(speeds) <= MAX_GEOMETRY_SPEED * (1 + 1e-12) and max(speeds) > 0.5 * MAX_GEOMETRY_SPEED
    assert steps.max() <= MAX_GEOMETRY_SPEED * app.robots.config.dt * (1 + 1e-9)
    run(app, 2.0)  # the first-order glide (time constant 0.05 s) has converged
    np.testing.assert_allclose(app.collisions.obstacles[first].obstacle.position, goal, atol=1e-12)
    placed = app.collisions.obstacles[first]
    assert not np.any(placed.obstacle.velocity) and placed.settled

    app.collisions.remove(first)
    assert [o.name for o in app.collisions.avoidance.obstacles] == [second]
    assert app.collisions.clear() == 1
    assert app.collisions.avoidance.obstacles == [] and not app.collisions.obstacles


@pytest.mark.parametrize("call, pattern", [
    (lambda app: app.collisions.add("cone"), r"unknown obstacle kind 'cone'"),
    (lambda app: app.collisions.add("sphere", radius=-1.0), r"radius"),
    (lambda app: app.collisions.add("sphere", height=1.0), r"unknown field 'height' for a sphere"),
    (lambda app: app.collisions.add("box", size=(0.1, 0.0, 0.1)), r"size"),
    (lambda app: app.collisions.add("sphere", center=(1e300, 0, 0)),
     r"center must have every component in \[-100, 100\]"),
    (lambda app: app.collisions.move("sphere-9", (0, 0, 0)), r"no obstacle 'sphere-9'"),
    (lambda app: app.collisions.remove("sphere-9"), r"no obstacle 'sphere-9'"),
    (lambda app: app.collisions.configure(safety_distance=0.06), r"detection_distance"),
    (lambda app: app.collisions.configure(approach_speed=10.0, detection_distance=0.01),
     r"unstable"),
    (lambda app: app.collisions.configure(approach_speed=1e3), r"approach_speed must be <= 10"),
    (lambda app: app.collisions.configure(margin=1.0), r"unknown collision setting 'margin'"),
    (lambda app: app.collisions.set_on("yes"), r"on \(True\) or off"),
])
def test_what_cannot_be_done_is_a_value_error_and_changes_nothing(app, call, pattern):
    app.collisions.add("sphere")
    before = app.scenes.scene()
    avoidance = app.collisions.avoidance
    with pytest.raises(ValueError, match=pattern):
        call(app)
    after = app.scenes.scene()
    assert {**after, "created": None} == {**before, "created": None}
    assert app.collisions.avoidance is avoidance
    assert app.robots.loops["main"].controller.collisions is avoidance


def test_settings_and_the_switch_reach_every_controller(dual_app):
    app = dual_app
    assert app.collisions.avoidance.self_collision  # two arms: self-collision on by default
    app.robots.set_ghost("qp:daqp")
    app.collisions.add("sphere")
    app.collisions.configure(safety_distance=0.01, detection_distance=0.08)
    for loop in app.robots.loops.values():
        assert loop.controller.collisions is app.collisions.avoidance
    avoidance = app.collisions.avoidance
    assert (avoidance.safety_distance, avoidance.detection_distance) == (0.01, 0.08)
    assert [o.name for o in app.collisions.avoidance.obstacles] == ["sphere-1"]
    app.robots.set_controller("qp:proxqp")
    assert app.robots.loops["main"].controller.collisions is app.collisions.avoidance
    app.collisions.set_on(False)
    assert all(loop.controller.collisions is None for loop in app.robots.loops.values())
    run(app, 0.05)
    snapshot = app.view.snapshot()
    assert snapshot["robots"]["main"]["collision_rows"] is None and not snapshot["collisions"]["checking"]
    assert np.isnan(snapshot["robots"]["main"]["trace"]["minimum_distance"]).all()
    app.collisions.set_on(True)
    assert app.robots.loops["ghost"].controller.collisions is app.collisions.avoidance
    app.collisions.configure(self_collision=False)
    assert all(second == "sphere-1" for _, second in app.collisions.avoidance.pairs)


def test_a_single_arm_checks_no_pair_without_an_obstacle(app):
    assert not app.collisions.avoidance.self_collision and app.collisions.avoidance.pairs == []
    run(app, 0.05)
    snapshot = app.view.snapshot()
    assert plots_of(snapshot) == PLOTS
    app.collisions.add("sphere")
    assert plots_of(app.view.snapshot()) == PLOTS + COLLISION_PLOTS


# -- scenes ---------------------------------------------------------------------------------

def test_a_scene_keeps_the_obstacles_and_the_settings(dual_app, dual, tmp_path):
    app = dual_app
    app.collisions.add("sphere", radius=0.03)
    app.collisions.add("capsule", ee=1, radius=0.02, length=0.1, axis=(1.0, 0.0, 0.0))
    moving = app.collisions.add("halfspace", normal=(0.0, 0.0, 1.0))
    app.collisions.move(moving, app.collisions.obstacles[moving].goal + [0.0, 0.0, -0.02])
    run(app, 0.1)  # mid-move: a velocity to keep
    app.collisions.configure(safety_distance=0.008, approach_speed=0.3)
    app.collisions.set_on(False)
    path = app.scenes.save("obstacles.json")
    saved = json.loads(path.read_text())
    assert saved["version"] == 3 and saved["collisions"]["on"] is False
    assert [o["id"] for o in saved["obstacles"]] == ["sphere-1", "capsule-2", "halfspace-3"]

    other = TeleopApp(dual, record_dir=tmp_path / "s2", scene_dir=tmp_path / "scenes")
    other.scenes.load("obstacles.json")
    for key in ("collisions", "obstacles", "constraints", "q"):
        assert other.scenes.scene()[key] == app.scenes.scene()[key]
    assert other.collisions.avoidance.to_dict() == app.collisions.avoidance.to_dict()
    assert all(loop.controller.collisions is None for loop in other.robots.loops.values())
    assert not other.collisions.obstacles[moving].settled
    np.testing.assert_array_equal(other.collisions.obstacles[moving].obstacle.velocity,
                                  app.collisions.obstacles[moving].obstacle.velocity)
    assert other.collisions.add("sphere") == "sphere-4"  # ids go on after the scene's
    other.collisions.set_on(True)
    assert other.robots.loops["main"].controller.collisions is other.collisions.avoidance


def test_the_damper_counts_on_the_plants_response_time_as_compare_does(sda10f, tmp_path):
    """On the physics plant the session's damper counts on the servos' time constant, as
    ``teleop compare --plant mujoco`` does (``Plan.with_response_time`` of the same
    ``PlantChoice``), ``1 / K = (d_i - d_s) / xi + tau`` written here; it keeps it when the
    operator changes a setting, writes it in its scenes, and a scene opened on another
    plant takes that plant's."""
    app = TeleopApp(sda10f, plant="mujoco", record_dir=tmp_path / "s1",
                    scene_dir=tmp_path / "scenes")
    tau = 1.0 / (2.0 * math.pi * 20.0)  # the default 20 Hz servos
    settings = {key: value for key, value in app.collisions.avoidance.to_dict().items()
                if key != "response_time"}
    plan = dataclasses.replace(load_scenario("obstacle", sda10f), collisions=settings)
    compared = plan.with_response_time(PlantChoice("mujoco").response_time).make_collisions()
    avoidance = app.collisions.avoidance
    assert avoidance.response_time == pytest.approx(tau, rel=1e-15)
    assert avoidance.gain == compared.gain
    xi, d_i, d_s = 0.5, 0.05, 0.005  # the defaults, written out
    assert (avoidance.approach_speed, avoidance.detection_distance,
            avoidance.safety_distance) == (xi, d_i, d_s)
    assert avoidance.gain == pytest.approx(1.0 / ((d_i - d_s) / xi + tau), rel=1e-12)  # 10.22
    assert app.robots.loops["main"].controller.collisions is avoidance

    app.collisions.configure(safety_distance=0.008, approach_speed=0.3)
    avoidance = app.collisions.avoidance
    assert avoidance.response_time == pytest.approx(tau, rel=1e-15)
    assert avoidance.gain == pytest.approx(1.0 / ((d_i - 0.008) / 0.3 + tau), rel=1e-12)
    assert app.robots.loops["main"].controller.collisions is avoidance
    saved = json.loads(app.scenes.save("late.json").read_text())
    assert saved["collisions"]["response_time"] == pytest.approx(tau, rel=1e-15)

    again = TeleopApp(sda10f, plant="mujoco", record_dir=tmp_path / "s2",
                      scene_dir=tmp_path / "scenes")
    again.scenes.load("late.json")
    assert again.collisions.avoidance.to_dict() == avoidance.to_dict()
    kinematic = TeleopApp(sda10f, record_dir=tmp_path / "s3", scene_dir=tmp_path / "scenes")
    kinematic.scenes.load("late.json")
    assert kinematic.collisions.avoidance.response_time == 0.0
    assert kinematic.collisions.avoidance.gain == 0.3 / (d_i - 0.008)
    assert "response_time" not in kinematic.scenes.scene()["collisions"]
    with pytest.raises(ValueError, match=r"^scene collisions: response_time"):
        kinematic.scenes.apply({**saved, "collisions": {**saved["collisions"],
                                                       "response_time": -1.0}})


def test_a_version_1_scene_still_loads_without_obstacles(sda10f, tmp_path):
    old = json.loads((DATA / "least_squares_scene.json").read_text())
    assert old["version"] == 1 and "obstacles" not in old
    app = TeleopApp(sda10f, record_dir=tmp_path, scene_dir=tmp_path)
    app.collisions.add("sphere")
    app.collisions.configure(safety_distance=0.007)
    app.scenes.apply(old)
    assert app.collisions.obstacles == {} and app.collisions.avoidance.obstacles == []
    assert app.collisions.avoidance.safety_distance == 0.007 and app.collisions.on  # the session's
    np.testing.assert_array_equal(app.robots.loops["main"].q, old["q"]["main"])


@pytest.mark.parametrize("change, pattern", [
    ({"collisions": {"on": "yes"}}, r"^scene collisions.on must be true or false"),
    ({"collisions": {"on": True, "margin": 1}}, r"^unknown scene collisions field 'margin'"),
    ({"collisions": {"on": True, "safety_distance": -1}}, r"^scene collisions: safety_distance"),
    ({"obstacles": [{"id": "a", "obstacle": {"kind": "cone"}}]},
     r"^scene obstacles\[0\]: unknown obstacle kind 'cone'"),
    ({"obstacles": [{"id": "a", "obstacle": {"kind": "sphere", "center": [0, 0, 0]}}]},
     r"^scene obstacles\[0\]: a sphere obstacle needs the field 'radius'"),
    ({"obstacles": [{"obstacle": {}}]}, r"^scene obstacles\[0\] must be an object with an 'id'"),
    ({"version": 1}, r"^scene 'collisions' needs version 2"),
])
def test_a_bad_scene_names_the_collision_field_and_changes_nothing(app, change, pattern):
    app.collisions.add("sphere")
    scene = {**app.scenes.scene(), **change}
    before = app.scenes.scene()
    with pytest.raises(ValueError, match=pattern):
        app.scenes.apply(scene)
    assert {**app.scenes.scene(), "created": None} == {**before, "created": None}


# -- what the view shows ----------------------------------------------------------------------

def near_obstacle(app) -> str:
    """A sphere whose surface is 2 cm from the tip, along the tool's z axis: inside the
    detection distance."""
    pose = tip(app)
    return app.collisions.add("sphere", radius=0.03,
                            center=pose.translation + 0.05 * pose.rotation[:, 2])


def test_the_status_and_highlights_are_the_controllers_rows(app, server):
    """The view shows the rows the main controller held on the measured tick, at the
    configuration its command was computed from (not computed again for the view)."""
    near_obstacle(app)
    app.console.nudge_target([0.0, 0.0, 0.01])
    run(app, 0.3)
    q = run_to_measure(app)
    snapshot = app.view.snapshot()
    shown = snapshot["robots"]["main"]["collision_rows"]
    expected = independent_rows(app, q=q)
    assert expected.size >= 1 and shown.pairs == expected.pairs
    np.testing.assert_allclose(shown.distances, expected.distances, atol=SAME)
    np.testing.assert_allclose(shown.witnesses, expected.witnesses, atol=SAME)
    np.testing.assert_allclose(shown.lower, expected.lower, atol=SAME)
    assert shown.minimum_distance == pytest.approx(expected.minimum_distance, abs=SAME)
    assert shown.closest_pair == expected.closest_pair
    # each is one of coal's distances of its pair (a link has several geometries)
    links = {pair.split(" | ")[0] for pair in expected.pairs}
    every = app.collisions.avoidance.distances(app.robot.model, pin_data(app, q))
    for pair, distance in zip(shown.pairs, shown.distances):
        assert min(abs(d - distance) for name, d in every if name == pair) < SAME
    # the status's words and the plotted trace
    words = collision_words(shown, [])
    assert f"minimum distance {1e3 * expected.minimum_distance:.2f} mm ({expected.closest_pair})" in words
    assert "held" not in words
    assert collision_words(shown, list(expected.pairs[:1])).endswith(
        f"; collision pairs held: {expected.pairs[0]}")
    assert collision_words(None, []) == ""
    trace = snapshot["robots"]["main"]["trace"]["minimum_distance"]
    assert trace[-1] == pytest.approx(min(expected.minimum_distance,
                                          app.collisions.avoidance.detection_distance), abs=SAME)

    # the view: a node per pair named after it, its witness segment, each link highlighted
    ui = TeleopUI(server, app, ControlThread(app))
    ui._draw(snapshot)
    assert set(ui.pair_highlights.pair_nodes) == set(expected.pairs)
    for pair in set(expected.pairs):  # its closest geometries' witness segment
        index = min((i for i, name in enumerate(expected.pairs) if name == pair),
                    key=lambda i: expected.distances[i])
        nodes = ui.pair_highlights.pair_nodes[pair]
        assert node_name(pair) in nodes["witness"].name
        np.testing.assert_allclose(np.asarray(nodes["witness"].points)[0],
                                   expected.witnesses[index], atol=1e-6)  # float32
        colour = distance_color(expected.distances[index], app.collisions.avoidance.safety_distance,
                                app.collisions.avoidance.detection_distance)
        assert tuple(np.asarray(nodes["witness"].colors)[0, 0]) == colour
    assert set(ui.pair_highlights.link_nodes) == links


def pin_data(app, q: np.ndarray) -> pin.Data:
    data = app.robot.model.createData()
    pin.forwardKinematics(app.robot.model, data, q)
    return data


def test_the_colour_goes_from_red_at_d_s_to_yellow_at_d_i():
    assert distance_color(0.005, 0.005, 0.05) == NEAR_COLOR
    assert distance_color(-0.01, 0.005, 0.05) == NEAR_COLOR
    assert distance_color(0.05, 0.005, 0.05) == FAR_COLOR
    middle = distance_color(0.0275, 0.005, 0.05)
    assert all(min(a, b) <= c <= max(a, b) for a, b, c in zip(NEAR_COLOR, FAR_COLOR, middle))


def test_the_dual_arms_pairs_are_the_controllers_rows(dual_app):
    """Both arms driven towards each other: the self-collision pairs the view shows are
    those of an avoidance built here, at the q the command was computed from."""
    app = dual_app
    for ee, side in ((0, -1.0), (1, 1.0)):
        for _ in range(8):
            app.console.nudge_target([0.0, 0.01 * side, 0.0], ee)
            run(app, 0.25)
    q = run_to_measure(app)
    shown = app.view.snapshot()["robots"]["main"]["collision_rows"]
    expected = independent_rows(app, q=q)
    assert shown.pairs == expected.pairs
    np.testing.assert_allclose(shown.distances, expected.distances, atol=SAME)
    assert shown.closest_pair == expected.closest_pair
    minimum, pair = app.collisions.avoidance.minimum_distance(q)
    if expected.size:
        assert minimum == pytest.approx(expected.minimum_distance, abs=SAME)


@pytest.fixture()
def server():
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield server
    server.stop()


def test_the_collisions_tab_adds_an_obstacle_from_its_inputs(app, server):
    ui = TeleopUI(server, app, ControlThread(app))
    inputs = ui.obstacle_panel.inputs["sphere"]
    assert set(inputs) == {"radius"}
    inputs["radius"].value = 0.025
    entry_id = ui.obstacle_panel.add("sphere")
    assert app.collisions.obstacles[entry_id].obstacle.radius == 0.025
    ui._draw(app.view.snapshot())
    assert entry_id in ui.obstacle_markers.nodes and "gizmo" in ui.obstacle_markers.nodes[entry_id]
    ui.collision_settings.safety_number.value = 8.0
    ui.collision_settings.apply()
    assert app.collisions.avoidance.safety_distance == pytest.approx(0.008)
    app.collisions.remove(entry_id)
    ui._draw(app.view.snapshot())
    assert entry_id not in ui.obstacle_markers.nodes


# -- the command line --------------------------------------------------------------------------

@pytest.mark.parametrize("args, message", [
    (["--safety-distance", "-1"], "--safety-distance: must be in [0, 1000] mm, got -1"),
    (["--approach-speed", "nan"], "--approach-speed: must be in (0, 10] m/s, got nan"),
    (["--detection-distance", "3"], "detection_distance (0.003 m) must exceed safety_distance"),
    (["--approach-speed", "5", "--rate", "50"], "is unstable at 50 Hz"),
])
def test_bad_collision_options_are_one_line_and_exit_2(args, message, tmp_path):
    result = subprocess.run([sys.executable, "-m", "web", "--port", str(free_port()),
                             "--record-dir", str(tmp_path), "--scene-dir", str(tmp_path), *args],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and message in result.stderr, result.stderr
