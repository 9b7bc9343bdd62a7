"""The experiments around the loop: the imperfect robot, the constraint-velocity rows, the
joint-space agreement, solver output kept off the console, the figures and the report
(docs/design.md section 15)."""

from __future__ import annotations

import base64
import json
import math
from html.parser import HTMLParser
from importlib.resources import files

import jsonschema
import numpy as np
import pinocchio as pin
import pytest

from constraints import Barrier, Hole
from constraints.kinematics import frame_placement
from controllers import CJMController, QPController
from teleop.experiments.compare import (
    ShadowedController,
    compare,
    joint_velocity_agreement,
    metrics_document,
    run_plan,
    write_outputs,
)
from teleop.plants.imperfect import Imperfections, ImperfectPlant
from teleop.experiments.plan import Plan, home_pose
from teleop.experiments.plots import overlap_groups
from teleop.experiments.scenarios import load_scenario
from teleop.experiments.solver_output import SolverOutputCapture
from teleop.loop import LoopConfig, StateObserverConfig, TeleopLoop, row_labels

SCHEMA = json.loads(files("teleop.experiments").joinpath("metrics.schema.json").read_text())
ALL_CONTROLLERS = ["cjm", "qp:proxqp", "qp:daqp", "qp:osqp", "mink:daqp"]
POLISHING = "Polishing not needed - no active set detected at optimal point"
#: columns that hold wall-clock times (not reproducible run to run)
TIMES = ("step_time_us", "tick_time_us")


# ----------------------------------------------------------------------------- rows


def test_row_labels_name_every_equality_row_in_words(sda10f):
    plan = load_scenario("multi", sda10f)
    floor = Barrier(sda10f.ee_frame, np.zeros(3), [0.0, 0.0, -1.0], [0.0, 0.0, 1.0])
    second = Hole.on_link(sda10f, plan.q0, distance=0.05)
    assert row_labels([*plan.make_constraints(), floor, second]) == (
        "lateral velocity at hole 1, direction 1 (m/s)",
        "lateral velocity at hole 1, direction 2 (m/s)",
        "normal velocity at plane 1 (m/s)",
        "lateral velocity at hole 2, direction 1 (m/s)",
        "lateral velocity at hole 2, direction 2 (m/s)",
    )


def test_row_velocities_equal_pinocchio_frame_velocities(sda10f):
    """Every row's C v_c, against the point velocity from Pinocchio's frame velocity (not
    the constraint's Jacobian rows), on the multi scenario (hole + plane)."""
    plan = load_scenario("multi", sda10f)
    constraints = plan.make_constraints()
    loop = TeleopLoop(sda10f, CJMController(sda10f, constraints), q0=plan.q0)
    model, data = sda10f.model, sda10f.model.createData()
    for step in range(1, 301):
        q = loop.q.copy()
        record = loop.tick(plan.target(step * 1e-3))
        if step % 50:
            continue
        pin.forwardKinematics(model, data, q, loop.last_qd)
        pin.updateFramePlacements(model, data)
        expected = []
        for constraint in constraints:
            frame = model.getFrameId(constraint.link)
            placement = data.oMf[frame]
            twist = pin.getFrameVelocity(model, data, frame, pin.LOCAL_WORLD_ALIGNED)
            point = constraint.point_world(placement)
            velocity = twist.linear + np.cross(twist.angular, point - placement.translation)
            expected.append(constraint.directions(placement) @ (placement.rotation.T @ velocity))
        np.testing.assert_allclose(record.constraint_velocity, np.concatenate(expected),
                                   rtol=1e-9, atol=1e-15)
        assert len(record.constraint_velocity_labels) == 3


def test_moving_geometry_is_subtracted_from_the_row_velocity():
    """On the moving trocar the link moves with the hole (5 mm at 0.25 Hz, ~8 mm/s): the
    velocity relative to the hole is the drift correction, up to the command's residual."""
    result = run_plan(load_scenario("moving-trocar"), "cjm", duration=2.0)
    difference = np.max(np.abs(result.constraint_velocity - result.drift_velocity))
    assert difference <= result.metrics()["constraint_velocity_residual_max_mps"] + 1e-15
    assert result.metrics()["constraint_velocity_max_mps"] < 1e-4  # not the hole's 8 mm/s


# ----------------------------------------------------------------------------- imperfect


@pytest.mark.parametrize("field, value", [
    ("encoder_noise", -1e-4), ("encoder_noise", math.nan), ("encoder_noise", "0.1"),
    ("latency", 1.5), ("latency", -1), ("latency", True),
    ("joint_time_constant", math.inf), ("seed", -3),
])
def test_bad_imperfections_are_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        Imperfections(**{field: value})


def test_latency_delays_the_command_by_whole_periods(ur5_instrument):
    plant = ImperfectPlant(Imperfections(latency=3), ur5_instrument.model, 1e-3)
    commands = [np.full(8, float(k + 1)) for k in range(6)]
    applied = [plant.actuate(c) for c in commands]
    for k in range(6):
        np.testing.assert_array_equal(applied[k], np.zeros(8) if k < 3 else commands[k - 3])


def test_first_order_joints_move_by_the_exact_integral(ur5_instrument):
    """From rest, a held command u: q(t) = u (t - tau (1 - exp(-t/tau))), so the mean
    velocity over period k is (q(k+1) - q(k)) / dt."""
    tau, dt = 0.02, 1e-3
    plant = ImperfectPlant(Imperfections(joint_time_constant=tau), ur5_instrument.model, dt)
    u = np.linspace(-1.0, 1.0, 8)

    def position(t):
        return u * (t - tau * (1.0 - math.exp(-t / tau)))

    for k in range(50):
        np.testing.assert_allclose(plant.actuate(u) * dt, position((k + 1) * dt) - position(k * dt),
                                   rtol=1e-12, atol=1e-18)


def test_encoder_noise_has_the_asked_deviation_and_follows_the_seed(ur5_instrument):
    model, q = ur5_instrument.model, ur5_instrument.q_home
    draws = np.array([ImperfectPlant(Imperfections(encoder_noise=1e-4, seed=7), model, 1e-3)
                      .sense(q) for _ in range(2)])
    np.testing.assert_array_equal(draws[0], draws[1])  # same seed, same first draw
    plant = ImperfectPlant(Imperfections(encoder_noise=1e-4, seed=7), model, 1e-3)
    noise = np.array([plant.sense(q) - q for _ in range(4000)])
    assert abs(noise.std() / 1e-4 - 1.0) < 0.03  # 32000 samples: 1 % standard error
    assert abs(noise.mean()) < 5e-6


class Spy:
    """A controller that records the configuration it is handed and the command it gives."""

    def __init__(self, controller):
        self.controller = controller
        self.seen, self.commands = [], []

    def __getattr__(self, name):
        return getattr(self.controller, name)

    def solve(self, q, twist):
        self.seen.append(q.copy())
        self.commands.append(self.controller.solve(q, twist))
        return self.commands[-1]


def test_the_controller_sees_the_noisy_q_and_the_robot_moves_with_the_late_command(ur5_instrument):
    robot = ur5_instrument
    hole = Hole.on_link(robot, robot.q_home, distance=0.2)
    spy = Spy(CJMController(robot, [hole]))
    imperfections = Imperfections(encoder_noise=1e-4, latency=2, seed=3)
    raw = LoopConfig(state_observer=StateObserverConfig(enabled=False))  # the encoders raw
    loop = TeleopLoop(robot, spy, plant=imperfections.plant(robot.model, 1e-3), config=raw)
    start = loop.ee_placement()
    target = start * pin.exp6(np.array([0.01, 0.0, 0.0, 0.0, 0.0, 0.0]))
    true_q, errors = [loop.q.copy()], []
    for _ in range(40):
        record = loop.tick(target)
        true_q.append(loop.q.copy())
        errors.append(record.constraint_error)
    noise = np.array(spy.seen) - np.array(true_q[:-1])
    assert 0.7e-4 < noise.std() < 1.3e-4
    np.testing.assert_array_equal(true_q[1], true_q[0])  # nothing arrived yet
    np.testing.assert_array_equal(true_q[2], true_q[0])
    for k in range(2, 40):
        np.testing.assert_allclose(true_q[k + 1], true_q[k] + 1e-3 * spy.commands[k - 2],
                                   rtol=0, atol=1e-15)
    # the error is the true one: the hole's offset at the true q, not at the measured one
    assert errors[-1] == pytest.approx(
        hole.violation(frame_placement(robot.model, loop.q, hole.link)), rel=1e-12)
    assert errors[-1] != pytest.approx(
        hole.violation(frame_placement(robot.model, spy.seen[-1], hole.link)), rel=1e-3)


def test_noisy_late_runs_are_deterministic_for_a_seed_and_recorded(tmp_path):
    plan = load_scenario("paper-hole")
    imperfect = Imperfections(encoder_noise=1e-4, latency=2, joint_time_constant=0.01, seed=5)
    config = LoopConfig()
    runs = [compare(plan, ["cjm", "qp:daqp"], config, duration=0.3, progress=False,
                    imperfections=imperfect) for _ in range(2)]
    other = run_plan(plan, "cjm", config, duration=0.3,
                     imperfections=Imperfections(encoder_noise=1e-4, latency=2,
                                                 joint_time_constant=0.01, seed=6))
    for spec in ("cjm", "qp:daqp"):
        first, second = runs[0][spec], runs[1][spec]
        for name, column in first.columns.items():
            if name not in TIMES:
                np.testing.assert_array_equal(column, second.columns[name], err_msg=name)
        np.testing.assert_array_equal(first.constraint_velocity, second.constraint_velocity)
        np.testing.assert_array_equal(first.joint_velocity_deviation,
                                      second.joint_velocity_deviation)
    assert not np.array_equal(other.columns["constraint_error"],
                              runs[0]["cjm"].columns["constraint_error"])
    # the noise is felt: the hole error is far above the perfect robot's 2.7e-7 m
    assert runs[0]["cjm"].metrics()["constraint_error_max_m"] > 1e-6
    write_outputs(plan, runs[0], config, 0.3, tmp_path, plots=False, imperfections=imperfect)
    document = json.loads((tmp_path / "metrics.json").read_text())
    jsonschema.validate(document, SCHEMA)
    assert document["imperfections"] == {"encoder_noise_rad": 1e-4, "latency_periods": 2,
                                         "joint_time_constant_s": 0.01, "seed": 5,
                                         "calibration_position_std_m": 0.0,
                                         "calibration_rotation_std_rad": 0.0}


# ----------------------------------------------------------------------------- agreement


def test_a_shadow_identical_to_the_reference_deviates_by_exactly_zero(ur5_instrument):
    """The shadows solve at the reference's own q and twist: an identical controller agrees
    bit for bit on every step, a different algorithm for the same problem to 1e-9."""
    plan = load_scenario("trocar-circle", ur5_instrument)
    deviations = joint_velocity_agreement(plan, ["cjm", "cjm:general"], duration=0.5)
    assert set(deviations) == {"cjm", "cjm:general"}
    np.testing.assert_array_equal(deviations["cjm"], np.zeros(500))
    plan_constraints = plan.make_constraints()
    reference = CJMController(ur5_instrument, plan_constraints)
    shadowed = ShadowedController(reference, {"twin": CJMController(ur5_instrument,
                                                                    plan_constraints)})
    loop = TeleopLoop(ur5_instrument, shadowed, q0=plan.q0)
    for k in range(200):
        loop.tick(plan.target((k + 1) * 1e-3))
    assert len(shadowed.deviations["twin"]) == 200
    assert max(shadowed.deviations["twin"]) == 0.0
    assert np.max(deviations["cjm:general"]) <= 1e-9
    assert np.max(deviations["cjm:general"]) > 0.0  # a different computation, not a copy


@pytest.mark.parametrize("scenario", ["paper-hole", "multi"])
def test_the_cjm_and_the_qps_command_the_same_joint_velocities(scenario):
    """10 s at 1 kHz, every step solved at the CJM's q and twist (what ``compare`` reports):
    daqp and proxqp agree with the CJM to 1e-6 rad/s (multi: 3 rows on 8 joints leave 5 DoF
    for the 6-D task, so the least-squares optimum is what they agree on)."""
    deviations = joint_velocity_agreement(load_scenario(scenario), ["cjm", "qp:daqp", "qp:proxqp"])
    for spec in ("qp:daqp", "qp:proxqp"):
        assert len(deviations[spec]) == 10_000
        deviation = float(np.max(deviations[spec]))
        print(f"{scenario} {spec}: max |qd - qd_cjm| = {deviation:.2e} rad/s")
        assert deviation <= 1e-6, (spec, deviation)


def test_bench_reports_the_deviation_from_the_first_controller(ur5_instrument):
    from teleop.experiments.bench import bench_controllers

    hole = Hole.on_link(ur5_instrument, ur5_instrument.q_home, distance=0.2)
    timings = bench_controllers(ur5_instrument, [hole], ["cjm", "qp:daqp", "cjm"], 30, 3)
    assert timings[0].joint_velocity_deviation_max == 0.0
    assert 0.0 < timings[1].joint_velocity_deviation_max <= 1e-6
    assert timings[2].joint_velocity_deviation_max == 0.0  # the same controller again


@pytest.mark.parametrize("run", [compare, joint_velocity_agreement])
def test_a_controller_listed_twice_is_refused(run, ur5_instrument):
    with pytest.raises(ValueError, match=r"specs.*'cjm' twice"):
        run(load_scenario("trocar-circle", ur5_instrument), ["cjm", "qp:daqp", "cjm"])


# ----------------------------------------------------------------------------- solver output


def _unconstrained_plan(robot) -> Plan:
    """No constraint at all: every osqp solve has no active set, so OSQP prints."""
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    return Plan("free", robot, q0, 0.05, lambda: [],
                lambda t: pin.SE3(start.rotation, start.translation + [0.01 * t, 0.0, 0.0]))


def test_osqp_prints_when_it_polishes_without_an_active_set(capfd, ur5_instrument):
    """The premise of the next test: called bare, the solver does write to the console."""
    QPController(ur5_instrument, [], solver="osqp").solve(ur5_instrument.q_home, np.full(6, 0.01))
    assert POLISHING in capfd.readouterr().out


def test_compare_keeps_the_solvers_off_the_console(capfd, ur5_instrument):
    results = compare(_unconstrained_plan(ur5_instrument), ["qp:osqp", "mink:osqp"],
                      progress=False)
    out, err = capfd.readouterr()
    assert out == "" and err == ""
    assert results["qp:osqp"].solver_messages[POLISHING] == 50  # one per step, counted
    assert any(message.startswith("SparseConversionWarning")
               for message in results["mink:osqp"].solver_messages)


def test_the_capture_restores_the_console(capfd):
    import os
    import sys

    with SolverOutputCapture() as capture:
        os.write(1, b"from C\n")
        print("from Python")
        print("to stderr", file=sys.stderr)
        captured = capture.collect()
        print("progress", file=capture.console)
    print("after")
    out, err = capfd.readouterr()
    assert captured == {"from C": 1, "from Python": 1, "to stderr": 1}
    assert out == "after\n" and err == "progress\n"


# ----------------------------------------------------------------------------- figures


def test_overlap_groups_join_curves_within_the_tolerance_and_say_by_how_much():
    base = np.array([[1.0, -2.0], [np.nan, 3.0]])
    groups = overlap_groups({"a": base, "b": base + 1e-4, "c": base * 1.01,
                             "d": np.where(np.isnan(base), 0.0, base)})
    assert [g.members for g in groups] == [("a", "b"), ("c",), ("d",)]
    assert groups[0].difference == pytest.approx(1e-4)
    assert "differ by at most 1.0e-04 m/s" in groups[0].overlap("m/s")
    assert groups[1].overlap("m/s") == ""


class _Page(HTMLParser):
    """The tags, image sources, link targets and table cells of a page."""

    def __init__(self):
        super().__init__()
        self.images, self.links, self.cells, self.best = [], [], [], []
        self._cell = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.images.append(attrs["src"])
        if "href" in attrs:
            self.links.append(attrs["href"])
        if tag == "td":
            self._cell = [attrs.get("class") == "best", ""]

    def handle_data(self, data):
        if self._cell is not None:
            self._cell[1] += data

    def handle_endtag(self, tag):
        if tag == "td" and self._cell is not None:
            self.cells.append(self._cell[1])
            if self._cell[0]:
                self.best.append(len(self.cells) - 1)
            self._cell = None


def test_multi_report_embeds_every_plot_lists_every_controller_and_marks_the_best(tmp_path):
    plan, config = load_scenario("multi"), LoopConfig()
    results = compare(plan, ALL_CONTROLLERS, config, duration=0.5, progress=False)
    paths = write_outputs(plan, results, config, 0.5, tmp_path)
    report = tmp_path / "report.html"
    assert report in paths
    page = _Page()
    page.feed(report.read_text(encoding="utf-8"))
    pngs = [p for p in paths if p.suffix == ".png"]
    embedded = [base64.b64decode(src.split(",", 1)[1]) for src in page.images
                if src.startswith("data:image/png;base64,")]
    assert len(embedded) == len(page.images) == len(pngs) >= 5
    assert sorted(embedded) == sorted(p.read_bytes() for p in pngs)
    assert page.links == []  # nothing to fetch
    for spec in ALL_CONTROLLERS:
        assert spec in page.cells
    # the best residual: qp:proxqp holds the rows to its 1e-10 tolerance, the others to
    # round-off; the marked ones are those within 1e-12 m/s (the measure's resolution) of
    # the smallest in metrics.json, and not every controller
    document = json.loads((tmp_path / "metrics.json").read_text())
    residuals = {s: m["constraint_velocity_residual_max_mps"]
                 for s, m in document["controllers"].items()}
    row = {spec: page.cells.index(spec) for spec in ALL_CONTROLLERS}
    marked = {spec for spec, start in row.items() if start + 3 in page.best}
    smallest = min(residuals.values())
    assert marked == {s for s, value in residuals.items() if value - smallest <= 1e-12}
    assert 0 < len(marked) < len(residuals)
    # the constraint-velocity figure has a panel per row, the plane's among them
    from teleop.experiments.plots import write_plots

    (tmp_path / "again").mkdir()
    figures = write_plots(plan, results, tmp_path / "again")
    panels = [f.panels for f in figures if f.path.name.startswith("constraint_velocity")]
    assert panels and all("normal velocity at plane 1 (m/s)" in p for p in panels)
    assert all(len(p) == 3 for p in panels)


def test_no_plots_writes_no_report(tmp_path):
    plan, config = load_scenario("paper-hole"), LoopConfig()
    results = compare(plan, ["cjm"], config, duration=0.05, progress=False)
    write_outputs(plan, results, config, 0.05, tmp_path, plots=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.csv", "metrics.json"]
    document = metrics_document(plan, results, config, 0.05)
    jsonschema.validate(document, SCHEMA)
    assert document["joint_velocity_reference"] is None  # one controller: nothing to compare
    assert document["controllers"]["cjm"]["joint_velocity_deviation_max_radps"] is None
