"""The browser session on the MuJoCo plant, without a browser (docs/design.md sections 5.3
and 17): each loop runs its own simulated robot, the wall's force at each port reaches the
snapshot, the status words, the plots and the arrow, and equals the wall's stiffness times
the instrument's offset from the port centre, computed here from Pinocchio's kinematics."""

from __future__ import annotations

import math
import time

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import HealthCheck, given, settings
from browser_helpers import free_port
from hypothesis import strategies as st

from constraints import Hole
from teleop.plants import MujocoPlant, PlantSettings
from teleop.plants import PlantChoice
from test_web_cli import serve
from web.app import ControlThread, PortReading, TeleopApp, port_words
from web.ui import PLANT_PLOTS, PLOTS, force_arrow, plot_series, plots_of

#: the port force a gentle motion of the operator stays below (N): the issue's target
GENTLE_FORCE = 0.2


def arrow_vector(force: np.ndarray) -> np.ndarray:
    """The port-force arrow's vector, written out here: along the force, 2 cm per tenfold
    force above 10 uN (2 cm at 0.1 mN, 6 cm at 10 mN); none at 10 uN or less."""
    magnitude = float(np.linalg.norm(force))
    if magnitude <= 1e-5:
        return np.zeros(3)
    return 0.02 * np.log10(magnitude / 1e-5) * force / magnitude


def run(app: TeleopApp, seconds: float) -> None:
    for _ in range(int(round(seconds * app.robots.config.rate))):
        app.step()


def nudge(app: TeleopApp, offset) -> None:
    target = app.console.target
    quaternion = pin.Quaternion(target.rotation)
    app.console.set_target(target.translation + np.asarray(offset),
                   [quaternion.w, quaternion.x, quaternion.y, quaternion.z])


def port_offset(robot, q: np.ndarray, hole: Hole) -> np.ndarray:
    """The link axis's offset from the hole centre at ``q``, written out here: the point
    of the axis nearest the centre minus the centre (world, m)."""
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    link = data.oMf[robot.model.getFrameId(hole.link)]
    axis = link.rotation @ hole.link_axis / np.linalg.norm(hole.link_axis)
    origin = link.translation
    nearest = origin + float(axis @ (hole.center - origin)) * axis
    return nearest - hole.center


@pytest.fixture()
def app(sda10f, tmp_path):
    return TeleopApp(sda10f, plant="mujoco", record_dir=tmp_path, scene_dir=tmp_path / "scenes")


def test_each_loop_runs_its_own_simulated_robot(app):
    main = app.robots.loops["main"]
    assert isinstance(main.plant, MujocoPlant) and main.plant.dt == app.robots.config.dt
    app.robots.set_ghost("qp:daqp")
    ghost = app.robots.loops["ghost"]
    assert isinstance(ghost.plant, MujocoPlant) and ghost.plant is not main.plant
    plant = main.plant
    app.robots.set_controller("qp:proxqp")  # same rate: the same simulated robot goes on
    assert app.robots.loops["main"].plant is plant and app.robots.loops["main"].q is not main.q
    app.robots.set_rate(500.0)  # a new period: new physics for every loop, at rest where it was
    assert {id(loop.plant) for loop in app.robots.loops.values()}.isdisjoint({id(plant), id(ghost.plant)})
    assert all(loop.plant.dt == pytest.approx(2e-3) for loop in app.robots.loops.values())
    # the simulated robot is where the loop says it is
    loop = app.robots.loops["main"]
    run(app, 0.05)
    q_sim = np.empty(app.robot.model.nq)
    loop.plant.joints.q_to_pinocchio(loop.plant.mj_data.qpos, q_sim)
    np.testing.assert_allclose(q_sim, loop.q, atol=1e-12)
    # the kinematic app has no plant
    kinematic = TeleopApp(app.robot, record_dir=app.record_dir, scene_dir=app.scene_dir)
    assert kinematic.robots.loops["main"].plant is None
    snapshot = kinematic.view.snapshot()
    assert snapshot["robots"]["main"]["ports"] == [] and plots_of(snapshot) == PLOTS


def test_a_moved_target_pushes_the_instrument_on_the_wall_and_the_view_says_how_hard(app):
    hole_id = app.constraints.add("hole", distance=0.08)
    run(app, 0.1)
    ports = app.view.snapshot()["robots"]["main"]["ports"]
    assert [port.id for port in ports] == [hole_id]
    assert ports[0].magnitude < 1e-4  # at rest on the port: the wall hardly pushes
    nudge(app, [0.0, 0.02, 0.0])  # 2 cm sideways: the motion caps make it gentle
    forces = []  # every control period's largest port force, read from the plant here
    first = app.ticker.ticks  # ticks 0, 20, 40... take the history samples (50 Hz at 1 kHz)
    for _ in range(1000):
        app.step()
        forces.append(np.linalg.norm(app.robots.loops["main"].plant.measures().port_forces, axis=1).max())
    peak = max(forces)
    assert 1e-3 < peak < GENTLE_FORCE, peak  # felt, and below the target
    # the plots' port-force trace: finite, in newtons, each sample the peak of the 20
    # periods since the one before (a 50 Hz sample of one period's force misses peaks)
    snapshot = app.view.snapshot()
    assert plots_of(snapshot) == PLOTS + PLANT_PLOTS
    t, series = plot_series(snapshot, PLANT_PLOTS[0])
    assert t.size == 55 and np.isfinite(series["main"]).all()  # 1.1 s at 50 Hz
    assert series["main"].max() == pytest.approx(peak, rel=1e-12)
    last = (first + len(forces) - 1) // 20 * 20 - first  # the last sample's tick, in forces
    periods = np.reshape(forces[last - 979:last + 1], (49, 20))  # each its 20 periods up to it
    np.testing.assert_allclose(series["main"][-49:], periods.max(axis=1), rtol=1e-12)
    # the status words (mN) and the arrow of the last reading
    (port,) = snapshot["robots"]["main"]["ports"]
    assert port_words([port]) == (f"port force {hole_id} {1e3 * port.magnitude:.2f} mN "
                                  f"(tissue {1e6 * port.displacement:.1f} µm)")
    for newtons, length in ((1e-4, 0.02), (1e-3, 0.04), (1e-2, 0.06), (0.1, 0.08)):
        reading = PortReading(hole_id, port.point, np.array([0.0, 0.0, newtons]), 0.0)
        arrow = force_arrow(reading)
        assert arrow[0, 1, 2] - arrow[0, 0, 2] == pytest.approx(length, abs=1e-15)
    arrow = force_arrow(port, clearance=0.03)  # its tip 3 cm from the port, pushing on it
    np.testing.assert_allclose(arrow[0, 1] - arrow[0, 0], arrow_vector(port.force), atol=1e-15)
    np.testing.assert_allclose(arrow[0, 1] + 0.03 * port.force / port.magnitude, port.point,
                               atol=1e-15)


@settings(max_examples=6, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(wall_stiffness=st.one_of(st.none(), st.floats(200.0, 5000.0)),
       lateral=st.floats(0.2e-3, 2e-3), angle=st.floats(0.0, 2 * math.pi))
def test_the_port_force_is_the_wall_stiffness_times_the_offset(sda10f, tmp_path, wall_stiffness,
                                                               lateral, angle):
    """A hole ``lateral`` m off the instrument's axis (any direction across it) with no
    drift gain: the controller holds the offset (no lateral velocity), the wall pushes;
    at rest the reading equals ``k`` x the offset computed here from the loop's q (1 %),
    towards the centre, and ``|F| = k`` x the reported displacement."""
    app = TeleopApp(sda10f, plant="mujoco", wall_stiffness=wall_stiffness, record_dir=tmp_path,
                    scene_dir=tmp_path / "scenes")
    app.robots.set_gain(0.0)
    q = app.robots.loops["main"].q.copy()
    hole = Hole.on_link(sda10f, q, distance=0.1)
    offset = port_offset(sda10f, q, hole)
    assert np.linalg.norm(offset) < 1e-9
    data = sda10f.model.createData()
    pin.framesForwardKinematics(sda10f.model, data, q)
    axis = data.oMf[sda10f.model.getFrameId(hole.link)].rotation @ hole.link_axis
    across = np.cross(axis, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    across = math.cos(angle) * across + math.sin(angle) * np.cross(axis, across)
    hole.center = hole.center + lateral * across
    hole_id = app.constraints.add(hole)
    stiffness = 1000.0 if wall_stiffness is None else wall_stiffness
    assert hole.tissue_stiffness == stiffness
    run(app, 1.0)  # the arm gives a little under the push, then rests
    (port,) = app.view.snapshot()["robots"]["main"]["ports"]
    offset = port_offset(sda10f, app.robots.loops["main"].q, hole)
    assert 0.9 * lateral < np.linalg.norm(offset) < 1.1 * lateral
    expected = -stiffness * offset
    assert port.id == hole_id
    assert np.linalg.norm(port.force - expected) <= 0.01 * np.linalg.norm(expected)
    assert port.displacement == pytest.approx(np.linalg.norm(offset), rel=0.01)
    assert port.magnitude == pytest.approx(stiffness * port.displacement, rel=0.01)


def test_the_session_wall_stiffness_reaches_a_scenes_holes(sda10f, tmp_path):
    saved = TeleopApp(sda10f, plant="mujoco", record_dir=tmp_path, scene_dir=tmp_path)
    saved.constraints.add("hole", distance=0.08)
    path = saved.scenes.save("wall.json")
    stiff = TeleopApp(sda10f, plant="mujoco", wall_stiffness=3000.0, record_dir=tmp_path,
                      scene_dir=tmp_path)
    stiff.scenes.load(path.name)
    (entry,) = stiff.constraints.entries.values()
    assert entry.constraint.tissue_stiffness == 3000.0
    run(stiff, 0.05)
    assert [port.id for port in stiff.view.snapshot()["robots"]["main"]["ports"]] == [entry.id]
    # and the scene's own stiffness without one
    own = TeleopApp(sda10f, plant="mujoco", record_dir=tmp_path, scene_dir=tmp_path)
    own.scenes.load(path.name)
    assert next(iter(own.constraints.entries.values())).constraint.tissue_stiffness == 1000.0


def test_home_resets_the_simulated_robot(app):
    nudge(app, [0.0, 0.0, 0.02])
    run(app, 0.3)
    app.console.home()  # no constraint: a reset
    loop = app.robots.loops["main"]
    np.testing.assert_allclose(loop.q, app.robot.q_home)
    q_sim = np.empty(app.robot.model.nq)
    loop.plant.joints.q_to_pinocchio(loop.plant.mj_data.qpos, q_sim)
    np.testing.assert_allclose(q_sim, app.robot.q_home, atol=1e-12)
    assert not np.any(loop.plant.mj_data.qvel)


@pytest.mark.parametrize("kwargs, message", [
    ({"plant": "bullet"}, "plant must be one of kinematic, mujoco, ros2, got 'bullet'"),
    ({"plant": "mujoco", "wall_stiffness": -1.0}, "wall_stiffness must be >= 0"),
    ({"plant": "mujoco", "wall_stiffness": 1e9}, "wall_stiffness must be <= 100000"),
    ({"plant": "mujoco", "wall_stiffness": float("nan")}, "wall_stiffness must be finite"),
    ({"plant": "mujoco", "plant_settings": {"payload": 1}}, "plant settings must be PlantSettings"),
])
def test_bad_plant_choices_are_refused_naming_the_field(sda10f, tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        TeleopApp(sda10f, record_dir=tmp_path, **kwargs)


def test_the_control_thread_runs_the_plant(app):
    """A generous no-starvation guard (2 shared cores): the thread runs the simulated
    robot period after period, without error, and counts its ticks on time."""
    app.constraints.add("hole", distance=0.08)
    control = ControlThread(app)
    control.start()
    try:
        time.sleep(2.0)
    finally:
        control.stop()
    timing = control.timing()
    assert control.error is None and timing.ticks > 200
    assert app.now == pytest.approx(timing.ticks * app.robots.config.dt)
    assert 0.0 < timing.on_time <= 1.0


def test_plant_choice_describes_itself():
    choice = PlantChoice("mujoco", PlantSettings(payload=0.5), 2000.0)
    assert choice.physical and "payload 0.5 kg" in choice.describe()
    assert "wall 2 N/mm" in choice.describe()
    assert not PlantChoice().physical and PlantChoice().make(None, 1e-3) is None


# -- the view (a real viser server, no browser: tests/test_browser_plant.py has the page) ----


def test_the_view_draws_the_force_arrow_the_status_figure_and_the_plot(app):
    import viser

    from web.ui import TeleopUI

    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        ui = TeleopUI(server, app, ControlThread(app))
        hole_id = app.constraints.add("hole", distance=0.08)
        run(app, 0.1)
        nudge(app, [0.012, 0.0, 0.0])
        run(app, 0.02)  # setting off: the wall pushes
        snapshot = app.view.snapshot()
        ui._draw(snapshot)
        ui.plots.draw(snapshot)
        (port,) = snapshot["robots"]["main"]["ports"]
        assert port.magnitude > 1e-2
        arrow = ui.port_arrows.arrows["main"][hole_id]
        assert arrow.name == f"/ports/{hole_id}" and arrow.visible
        segments = np.asarray(arrow.points, dtype=float)
        # viser holds float32 points: a few float32 round-offs of coordinates under 1 m
        float32 = 4 * float(np.finfo(np.float32).eps)
        np.testing.assert_allclose(segments[0, 1] - segments[0, 0],
                                   arrow_vector(port.force), atol=float32)
        # its tip on the hole's ring, on the side the wall pushes from
        ring = ui.constraint_drawer.ring_radius_at(
            snapshot["robots"]["main"]["constraints"][hole_id])
        np.testing.assert_allclose(segments[0, 1], port.point - ring * port.force / port.magnitude,
                                   atol=float32)
        assert f"port force {hole_id} {1e3 * port.magnitude:.2f} mN" in ui.status_panel.details.content
        # the status line: the hole's link named, the force in mN, the arrow's scale
        assert (f"port force {hole_id} **{1e3 * port.magnitude:.2f} mN** (arrow 2 cm at "
                "0.1 mN, 2 cm more per tenfold force)") in ui.status_panel.summary.content
        # the largest force the plots show, in the status line once they have drawn it
        ui._draw(snapshot)
        largest = np.nanmax(snapshot["robots"]["main"]["trace"]["port_force"])
        assert largest > 1e-3  # the drag's start, sampled (the last periods are not yet)
        assert f"; the largest in the last 10 s {1e3 * largest:.2f} mN (arrow" in \
            ui.status_panel.summary.content
        link = app.constraints.entries[hole_id].constraint.link
        assert f"placed: {hole_id} on `{link}`" in ui.status_panel.summary.content
        label = ui.constraint_markers.nodes[hole_id]["label"]  # and in the scene, above the hole
        assert label.text == f"{hole_id} on {link}"
        np.testing.assert_allclose(label.position, port.point + [0.0, 0.0, 0.06], atol=1e-3)
        details = ui.status_panel.details.content
        assert "% of ticks on time" in details and "physics included" in details \
            and "**plant** MuJoCo plant at 2000 Hz" in details
        assert ui.plots.handles["port_force"].title.startswith("port force, the largest (")
        assert np.isfinite(ui.plots.handles["port_force"].data[1]).all()
        # a ghost gets its own arrows, under its own root; without it they go
        app.robots.set_ghost("qp:daqp")
        run(app, 0.05)
        ui.scene.ghost_seen = -1e9  # drawn at once (no plots to wait for here)
        ui._draw(app.view.snapshot())
        assert ui.port_arrows.arrows["ghost"][hole_id].name == f"/ghost/ports/{hole_id}"
        app.robots.set_ghost(None)
        ui._draw(app.view.snapshot())
        assert "ghost" not in ui.port_arrows.arrows
        app.constraints.remove(hole_id)
        run(app, 0.01)
        ui._draw(app.view.snapshot())
        assert ui.port_arrows.arrows["main"] == {}
    finally:
        server.stop()


# -- the command line ---------------------------------------------------------------------------


@pytest.mark.parametrize("args, message", [
    (["--plant", "bullet"], "argument --plant: invalid choice: 'bullet'"),
    (["--wall-stiffness", "2"], "--wall-stiffness needs --plant mujoco or ros2"),
    (["--payload", "1", "--wall-stiffness", "2", "--coulomb-friction", "1"],
     "--wall-stiffness needs --plant mujoco or ros2; --payload, --coulomb-friction need "
     "--plant mujoco"),
    (["--plant", "mujoco", "--wall-stiffness=-1"],
     "argument --wall-stiffness: must be in [0, 100] N/mm, got -1"),
    (["--plant", "mujoco", "--wall-stiffness", "1000"],
     "argument --wall-stiffness: must be in [0, 100] N/mm, got 1000"),
    (["--plant", "mujoco", "--payload=-1"], "argument --payload: must be in [0, 100] kg, got -1"),
    (["--plant", "mujoco", "--payload", "nan"],
     "argument --payload: must be in [0, 100] kg, got nan"),
    (["--plant", "mujoco", "--payload", "1e9"],
     "argument --payload: must be in [0, 100] kg, got 1e+09"),
    (["--plant", "ros2", "--wall-stiffness", "1", "--payload", "1"],
     "--payload needs --plant mujoco"),
])
def test_bad_plant_options_are_one_line_and_exit_2(args, message, capsys):
    from web import cli as web_cli

    try:
        code = web_cli.main([*args, "--port", str(free_port())])
    except SystemExit as exit_:  # argparse's own refusals exit from the parser
        code = exit_.code
    assert code == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and message in err, err


def test_teleop_web_plant_mujoco_starts_and_says_what_it_runs_on():
    """``python -m web --plant mujoco ...`` as a user starts it (bounded): its start line
    names the plant; Ctrl-C stops it with exit code 0."""
    out, err, code = serve("--plant", "mujoco", "--wall-stiffness", "2", "--payload", "0.5")
    assert code == 0, err
    assert "(controller cjm), on the MuJoCo plant at 2000 Hz, 20 Hz servos, payload 0.5 kg, " \
        "abdominal wall 2 N/mm; Ctrl-C stops" in out, out
    assert "Traceback" not in err, err
