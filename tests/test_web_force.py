"""Force control in the page's app (issue 36 item 5, docs/design.md 21.6), without a
browser: the tissue placed under the tool, the hybrid law on the chosen axes, the contact
force against stiffness x penetration from Pinocchio's kinematics of the simulated robot
(an independent reference), the setpoint and axes taken at once, the refusals by name,
and the compiled hot path back when force control is off."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from teleop.loop.force_controlled import ForceControlled
from teleop.loop.hybrid_force_motion import HybridForceMotion
from teleop.plants.tissue import DEFAULT_TISSUE_STIFFNESS
from web.app import TeleopApp
from web.app.force_control import FILTER_CUTOFF, TISSUE_GAP, force_gain_at
from web.app.limits import MAX_RATE, MIN_RATE


@pytest.fixture
def app(sda10f, tmp_path):
    return TeleopApp(sda10f, plant="mujoco", record_dir=tmp_path, scene_dir=tmp_path / "scenes")


def _true_contact(app) -> tuple[float, float]:
    """The tissue's force from stiffness x penetration at the simulated robot's tip
    (Pinocchio's kinematics of MuJoCo's qpos), and the plant's reported force."""
    loop, tissue = app.robots.loops["main"], app.force.tissue
    q = loop.plant.mj_data.qpos.copy()
    data = app.robot.model.createData()
    pin.framesForwardKinematics(app.robot.model, data, q)
    tip = data.oMf[app.robot.ee_frame_id].translation
    depth = max(0.0, float((tissue.point - tip) @ tissue.normal))
    return tissue.stiffness * depth, float(np.linalg.norm(loop.plant.measures().contact_forces[0]))


def test_force_control_presses_the_tissue_at_the_setpoint(app):
    for _ in range(50):
        app.step()
    tip = app.robots.loops["main"].ee_placements()[0]
    app.force.place_tissue()
    tissue = app.force.tissue
    np.testing.assert_allclose(tissue.point, tip.translation + TISSUE_GAP * tip.rotation[:, 2])
    np.testing.assert_allclose(tissue.normal, -tip.rotation[:, 2])
    app.force.set_enabled(True)
    assert isinstance(app.robots.loops["main"].controller, ForceControlled)
    assert app.robots.loops["main"].compiled is None  # the law needs the Python path
    for _ in range(3000):  # 2 mm at 1 cm/s, then the force loop settles (g = 0.067)
        app.step()
    expected, reported = _true_contact(app)
    assert expected == pytest.approx(1.0, abs=0.01) and reported == pytest.approx(expected,
                                                                                  rel=1e-3)
    state = app.view.snapshot()["force"]
    assert state["enabled"] and state["history"].shape[0] > 100
    np.testing.assert_allclose(np.linalg.norm(state["contact"]), reported, rtol=1e-9)
    # the setpoint is taken at once by the running law
    app.force.set_setpoint([0.0, 0.0, 2.0])
    for _ in range(3000):
        app.step()
    expected, _ = _true_contact(app)
    assert expected == pytest.approx(2.0, abs=0.02)
    assert app.robots.last_records["main"].status != "failed"
    # off: the plain controller and the compiled hot path again
    app.force.set_enabled(False)
    assert not isinstance(app.robots.loops["main"].controller, ForceControlled)
    assert app.robots.loops["main"].compiled is not None


def test_force_control_refuses_what_it_cannot_do_by_name(app, sda10f, tmp_path):
    with pytest.raises(ValueError, match="place the tissue first"):
        app.force.set_enabled(True)
    with pytest.raises(ValueError, match="within 5 N"):
        app.force.set_setpoint([0.0, 0.0, 6.0])
    with pytest.raises(ValueError, match="force setpoint"):
        app.force.set_setpoint([0.0, np.nan, 1.0])
    with pytest.raises(ValueError, match="at least one force axis"):
        app.force.set_axes([False, False, False])
    kinematic = TeleopApp(sda10f, record_dir=tmp_path, scene_dir=tmp_path / "scenes")
    with pytest.raises(ValueError, match="kinematic plant has no body"):
        kinematic.force.place_tissue()
    assert app.force.setpoint.tolist() == [0.0, 0.0, 1.0] and app.force.axes == (False, False,
                                                                                   True)


@pytest.mark.parametrize("rate", [250.0, 2000.0])
def test_force_control_presses_at_the_setpoint_at_other_rates(sda10f, tmp_path, rate):
    """The gain is palpation's (1 (m/s)/N) where the check accepts it, else 0.9 of the
    largest it accepts (250 Hz: 0.69); the tissue is pressed at 1 N either way."""
    app = TeleopApp(sda10f, plant="mujoco", rate=rate, record_dir=tmp_path,
                    scene_dir=tmp_path / "scenes")
    app.force.place_tissue()
    app.force.set_enabled(True)
    for _ in range(int(4.0 * rate)):
        app.step()
    expected, reported = _true_contact(app)
    assert expected == pytest.approx(1.0, abs=0.01) and reported == pytest.approx(expected,
                                                                                  rel=1e-3)


@pytest.mark.parametrize("rate", [MIN_RATE, 100.0, 250.0, 500.0, 1000.0, 2000.0, MAX_RATE])
def test_the_page_law_is_inside_its_stability_check_at_every_rate(rate):
    dt = 1.0 / rate
    gain = force_gain_at(DEFAULT_TISSUE_STIFFNESS, dt)
    assert 0.0 < gain <= 1.0
    HybridForceMotion((False, False, True), (0, 0, 1), gain, DEFAULT_TISSUE_STIFFNESS, dt,
                      filter_cutoff=FILTER_CUTOFF)  # accepted: no ValueError
    with pytest.raises(ValueError, match="force_gain"):  # the share is near the bound
        HybridForceMotion((False, False, True), (0, 0, 1), 1.2 * gain / 0.9 if gain < 1.0
                          else 1e3, DEFAULT_TISSUE_STIFFNESS, dt, filter_cutoff=FILTER_CUTOFF)


def test_a_scene_keeps_the_tissue_and_the_law_settings(app, sda10f, tmp_path):
    """Saved and opened in a fresh page: the same tissue (every field) and settings, the
    plants pressing it again (the contact force against stiffness x penetration), force
    control off until the operator turns it on; a scene without a tissue takes it away."""
    app.force.place_tissue()
    app.force.set_setpoint([0.5, 0.0, 1.5])
    app.force.set_axes([True, False, True])
    path = app.scenes.save("pressed.json")
    saved = app.force.tissue
    other = TeleopApp(sda10f, plant="mujoco", record_dir=tmp_path,
                      scene_dir=tmp_path / "scenes")
    other.scenes.load(path.name)
    tissue = other.force.tissue
    assert tissue is not None and tissue.to_dict() == saved.to_dict()
    np.testing.assert_array_equal(tissue.point, saved.point)
    assert other.force.setpoint.tolist() == [0.5, 0.0, 1.5]
    assert other.force.axes == (True, False, True) and not other.force.enabled
    assert other.robots.loops["main"].plant.tissues == (tissue,)
    other.force.set_enabled(True)
    other.force.set_axes([False, False, True])
    other.force.set_setpoint([0.0, 0.0, 1.0])
    for _ in range(3000):
        other.step()
    expected, reported = _true_contact(other)
    assert expected == pytest.approx(1.0, abs=0.01) and reported == pytest.approx(expected,
                                                                                  rel=1e-3)
    # a scene saved before a tissue was placed takes it away, and force control with it
    bare = TeleopApp(sda10f, plant="mujoco", record_dir=tmp_path,
                     scene_dir=tmp_path / "scenes")
    other.scenes.apply(bare.scenes.scene())
    assert other.force.tissue is None and not other.force.enabled
    assert other.robots.loops["main"].plant.tissues == ()


@pytest.mark.parametrize("change, message", [
    (lambda f: f["tissue"].update(stiffness=1e9), r"force\.tissue\.stiffness must be <= 100000"),
    (lambda f: f["tissue"].update(damping=-1.0), r"force\.tissue\.damping must be >= 0"),
    (lambda f: f["tissue"].update(normal=[0, 0, 0]), r"force\.tissue\.normal must be a direction"),
    (lambda f: f["tissue"].update(colour=1), "unknown scene force.tissue field 'colour'"),
    (lambda f: f["tissue"].update(normal=[0, 0, "up"]), r"force\.tissue\.normal must be"),
    (lambda f: f.update(setpoint=[0, 0, 9]), r"force\.setpoint must have every component"),
    (lambda f: f.update(axes=[False, False, False]), "force.axes must be 3 booleans"),
    (lambda f: f.update(axes="z"), "force.axes must be 3 booleans"),
    (lambda f: f.pop("axes"), "'force' must be null or an object"),
])
def test_a_bad_force_entry_in_a_scene_is_refused_by_name_and_changes_nothing(app, change,
                                                                             message):
    app.force.place_tissue()
    scene = app.scenes.scene()
    change(scene["force"])
    before = app.force.tissue
    with pytest.raises(ValueError, match=message):
        app.scenes.apply(scene)
    assert app.force.tissue is before


def test_a_tissue_in_a_scene_needs_the_physics_plant(app, sda10f, tmp_path):
    app.force.place_tissue()
    kinematic = TeleopApp(sda10f, record_dir=tmp_path, scene_dir=tmp_path / "scenes")
    with pytest.raises(ValueError, match="a tissue needs the mujoco plant"):
        kinematic.scenes.apply(app.scenes.scene())
    assert kinematic.force.tissue is None
    old = app.scenes.scene()
    old["version"] = 2
    with pytest.raises(ValueError, match="scene 'force' needs version 3"):
        app.scenes.apply(old)
    del old["force"]
    app.scenes.apply(old)  # a version 2 scene leaves the page's force control as it is
    assert app.force.tissue is not None


def test_the_status_leaves_the_force_axes_to_the_law(app):
    """Pressing 1 N, the tip sits 17 mm beyond its target along the tool's z (the tissue
    decides, not the target): the page does not call that a position short of the
    target; it counts the other axes (here the tool's x and y, within a millimetre)."""
    app.force.place_tissue()
    app.force.set_enabled(True)
    for _ in range(4000):
        app.step()
    placement = app.robots.loops["main"].ee_placements()[0]
    error = app.console.inputs[0].target.translation - placement.translation
    along_tool = placement.rotation.T @ error
    assert abs(along_tool[2]) > 0.01  # the tissue holds the tip off its target
    limitation = app.view.limitation("main")
    assert "short of the target" not in limitation.words
    assert limitation.distance == pytest.approx(float(np.linalg.norm(along_tool[:2])),
                                                abs=1e-12)
    app.force.set_enabled(False)  # the target owns every axis again
    assert app.view.limitation("main").distance == pytest.approx(float(np.linalg.norm(error)),
                                                            abs=1e-3)


def test_a_scene_whose_loops_cannot_be_built_leaves_the_force_control_as_it_was(app):
    """The scene's tissue and settings are taken before its loops are built (their plants
    need the tissue); a loop that cannot be built (a controller spec only the build
    refuses) puts back the page's tissue, settings, state and plot, and its loops."""
    app.force.place_tissue()
    app.force.set_enabled(True)
    for _ in range(200):
        app.step()
    kept = (app.force.tissue, app.force.setpoint.copy(), app.force.axes, app.force.enabled,
            len(app.force.history), app.robots.loops["main"])
    scene = app.scenes.scene()
    scene["force"]["tissue"]["point"][2] += 0.01
    scene["force"]["setpoint"] = [0.0, 0.0, 2.0]
    scene["controllers"]["main"] = "qp:no-such-solver"
    with pytest.raises(ValueError, match="no-such-solver"):
        app.scenes.apply(scene)
    assert app.force.tissue is kept[0] and app.force.setpoint.tolist() == kept[1].tolist()
    assert (app.force.axes, app.force.enabled, len(app.force.history),
            app.robots.loops["main"]) == kept[2:]


def test_a_huge_normal_is_a_direction_like_any_other():
    """A normal of 1e308 along z is the direction z (its norm would overflow: the tissue
    scales it by its largest component first)."""
    from web.scene import _force

    setup = _force({"version": 3, "force": {
        "tissue": {"point": [0, 0, 0], "normal": [0.0, 1e308, 1e308]},
        "setpoint": [0, 0, 1], "axes": [False, False, True]}})
    assert setup is not None
    np.testing.assert_allclose(setup.tissue.normal, [0.0, 2 ** -0.5, 2 ** -0.5], rtol=1e-15)
