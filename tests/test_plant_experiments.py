"""Experiments on the MuJoCo physics plant (docs/design.md section 17, docs/cli.md): every
scenario runs on it for every controller, the port force is the wall's stiffness times the
tissue's displacement, the smoothness figures match computations written here, and the
command line's plant options reach metrics.json, the report and session files."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from importlib.resources import files

import jsonschema
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from constraints import Hole
from teleop.experiments.bench import format_table, run_bench
from teleop.experiments.compare import compare, metrics_document, run_plan
from teleop.experiments.plan import Plan
from teleop.plants.choice import PlantChoice
from teleop.experiments.results import BODY_METRIC_KEYS
from teleop.experiments.scenarios import SCENARIOS, load_scenario
from teleop.experiments.sessions import load_session, session_plant
from teleop.experiments.smoothness import joint_jerk_rms, power_fraction_above
from teleop.loop import LoopConfig
from teleop.plants import PlantSettings
from teleop.plants.walls import has_wall

SCHEMA = json.loads(files("teleop.experiments").joinpath("metrics.schema.json").read_text())
ALL_CONTROLLERS = ["cjm", "qp:proxqp", "qp:daqp", "qp:osqp", "mink:daqp"]
MUJOCO = PlantChoice("mujoco")


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_every_scenario_runs_on_the_physics_plant_for_every_controller(scenario):
    plan = load_scenario(scenario)
    duration = 0.2
    results = compare(plan, ALL_CONTROLLERS, LoopConfig(), duration=duration, progress=False,
                      agreement=False, plant=MUJOCO)
    document = metrics_document(plan, results, LoopConfig(), duration, plant=MUJOCO)
    jsonschema.validate(document, SCHEMA)
    assert document["plant"]["kind"] == "mujoco"
    holes = [c for c in plan.make_constraints() if has_wall(c)]
    for spec, result in results.items():
        metrics = result.metrics()
        assert result.steps == 200
        assert metrics["failed_steps"] == 0, (spec, metrics["first_failure"])
        assert len(metrics["ports"]) == len(holes), spec
        for key in BODY_METRIC_KEYS:
            if key.startswith("interface_"):  # the interface's check is off by default
                assert metrics[key] is None, (spec, key)
            elif key in ("hole_error_max_m", "port_force_peak_spring_n",
                         "port_force_peak_damper_n") and not holes:
                assert metrics[key] is None
            else:
                assert np.isfinite(metrics[key]) and metrics[key] >= 0, (spec, key)
        # the drives carry the robot: a real torque, within the URDF's effort limits
        assert 0.0 < metrics["torque_ratio_max"] <= 1.0 + 1e-12, spec


def no_damping_plan(stiffness: float) -> Plan:
    """trocar-circle with a wall that is a pure spring (no damping), so that the force is
    the stiffness times the displacement at every step."""
    plan = load_scenario("trocar-circle")

    def make() -> list[Hole]:
        hole = Hole.on_link(plan.robot, plan.q0, distance=0.2)
        return [Hole(hole.link, hole.center, hole.link_axis, tissue_stiffness=stiffness,
                     tissue_damping=0.0)]

    return Plan(plan.name, plan.robot, plan.q0, plan.duration, make, plan.target)


@pytest.mark.parametrize("stiffness, override", [(1000.0, None), (1000.0, 2500.0)])
def test_the_port_force_is_the_stiffness_times_the_displacement(stiffness, override):
    plan = no_damping_plan(stiffness)
    plant = PlantChoice("mujoco", PlantSettings(payload=0.5), wall_stiffness=override)
    result = run_plan(plan, "cjm", duration=0.5, plant=plant)
    k = override or stiffness
    (name,) = result.port_names
    force = np.linalg.norm(result.port_forces[name], axis=1)
    displacement = result.port_displacements[name]
    np.testing.assert_allclose(force, k * displacement, rtol=1e-9, atol=1e-12)
    metrics = result.metrics()
    assert metrics["port_force_max_n"] == pytest.approx(k * metrics["port_displacement_max_m"],
                                                        rel=1e-9)
    assert metrics["ports"][name]["force_max_n"] == metrics["port_force_max_n"]
    assert metrics["port_displacement_max_m"] > 1e-7  # the payload makes the wall work
    # MuJoCo's port is taken at the last physics step's start, Pinocchio's hole offset at
    # the period's end: apart by the lateral motion over that physics step, at most its
    # lateral speed times the step. The measured speed is the period's mean (the plant's
    # mean velocity); under the servos' acceleration the speed at the period's end departs
    # from it (by up to 1.4x here): bound with twice the larger of this and the last mean.
    offset = result.constraint_errors[name]
    speed = np.linalg.norm(result.constraint_velocity, axis=1)
    speed = np.maximum(speed, np.concatenate([speed[:1], speed[:-1]]))
    step = 1.0 / PlantSettings().physics_rate
    assert np.all(np.abs(displacement - offset) <= 2.0 * speed * step + 1e-12)


def test_the_kinematic_plant_measures_smoothness_and_no_body():
    plan = load_scenario("fast-lateral")
    result = run_plan(plan, "cjm", duration=0.6)
    metrics = result.metrics()
    for key in ("port_force_max_n", "port_force_rms_n", "port_displacement_max_m",
                "torque_ratio_max", "actuator_saturated_steps"):
        assert metrics[key] is None, key
    assert metrics["ports"] == {}
    assert metrics["hole_error_max_m"] == metrics["constraint_error_max_m"]
    # the jerk written out here: the second difference of the commands, per joint
    qd = result.commanded_joint_velocity
    jerk = np.diff(qd, n=2, axis=0) / 1e-6
    expected = max(math.sqrt(float(np.mean(jerk[:, j] ** 2))) for j in range(qd.shape[1]))
    assert metrics["joint_jerk_rms_radps3"] == pytest.approx(expected, rel=1e-12)
    assert expected > 0


def test_the_jerk_of_a_sinusoidal_command_is_a_w_squared_over_root_two():
    """``qd = A sin(w t)`` on one joint over whole periods: the jerk is ``-A w^2 sin(w t)``,
    RMS ``A w^2 / sqrt 2``; the second difference sees it times ``sinc``-like
    ``(2 - 2 cos(w dt)) / (w dt)^2``."""
    dt, amplitude, omega = 1e-3, 0.3, 2 * math.pi * 2.0
    t = np.arange(5000) * dt  # 10 periods
    commands = np.zeros((len(t), 3))
    commands[:, 1] = amplitude * np.sin(omega * t)
    commands[:, 2] = 0.1 * amplitude * np.sin(omega * t)
    discrete = (2 - 2 * math.cos(omega * dt)) / (omega * dt) ** 2
    expected = amplitude * omega ** 2 / math.sqrt(2) * discrete
    assert joint_jerk_rms(commands, dt) == pytest.approx(expected, rel=1e-3)
    assert joint_jerk_rms(commands[:2], dt) == 0.0
    # a command ramping at constant acceleration has no jerk
    assert joint_jerk_rms(np.outer(t, [1.0, -2.0]), dt) == pytest.approx(0.0, abs=1e-6)


def test_the_power_above_3_hz_of_two_sinusoids_and_a_trend():
    """``v = cos(2 pi 1 t) + 0.5 cos(2 pi 10 t) + a line``, whole periods: the power splits
    1 : 0.25, so a fifth is above 3 Hz; the line is detrended away. (Cosines over whole
    periods are orthogonal to a line up to the sampling's ``O(1 / steps)``: the detrending
    leaves them.)"""
    dt = 1e-3
    t = np.arange(4000) * dt
    signal = np.cos(2 * np.pi * t) + 0.5 * np.cos(2 * np.pi * 10 * t)
    velocity = np.column_stack([signal, np.zeros_like(t), np.zeros_like(t)])
    assert power_fraction_above(velocity, dt) == pytest.approx(0.2, abs=1e-5)
    velocity[:, 1] = 0.05 + 0.3 * t  # a trend: not power
    assert power_fraction_above(velocity, dt) == pytest.approx(0.2, abs=1e-5)
    assert power_fraction_above(np.zeros((100, 3)), dt) == 0.0


@settings(max_examples=30, deadline=None)
@given(cycles=st.integers(1, 60), amplitude=st.floats(1e-4, 1.0), phase=st.floats(0, 6.28))
def test_a_sinusoid_on_a_frequency_bin_is_all_below_or_all_above_3_hz(cycles, amplitude, phase):
    """``cycles`` whole periods in 2 s: the frequency ``cycles / 2`` Hz falls on one FFT
    bin (up to the detrending's leakage, small against a whole-period sinusoid)."""
    dt, steps = 1e-3, 2000
    t = np.arange(steps) * dt
    frequency = cycles / (steps * dt)
    velocity = amplitude * np.sin(2 * np.pi * frequency * t + phase)[:, None]
    fraction = power_fraction_above(velocity, dt)
    assert 0.0 <= fraction <= 1.0
    # the detrending removes the sinusoid's own best line: at most 2 / cycles of its power
    leak = 3.0 / cycles
    if frequency > 3.0:
        assert fraction >= 1.0 - leak
    else:
        assert fraction <= leak


def teleop(*args: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "teleop.cli", *args], capture_output=True,
                          text=True, timeout=600, cwd=cwd)


def test_compare_on_the_physics_plant_from_the_command_line(tmp_path):
    out = tmp_path / "out"
    run = teleop("compare", "--plant", "mujoco", "--payload", "0.5", "--scenario",
                 "fast-lateral", "--controllers", "cjm,qp:daqp", "--duration", "0.3",
                 "--wall-stiffness", "2", "--coulomb-friction", "0.1", "--out", str(out),
                 "--interface-limits", "count", "--quiet")
    assert run.returncode == 0, run.stderr
    document = json.loads((out / "metrics.json").read_text())
    jsonschema.validate(document, SCHEMA)
    assert document["schema_version"] == 9  # 8: the plant's interface and wall parts (17); 9: failures
    plant = document["plant"]
    assert plant["kind"] == "mujoco" and plant["wall_stiffness_n_per_m"] == 2000.0
    assert plant["settings"]["payload_kg"] == 0.5
    assert plant["settings"]["coulomb_friction_nm"] == 0.1
    for spec in ("cjm", "qp:daqp"):
        metrics = document["controllers"][spec]
        assert metrics["port_force_max_n"] > 0 and metrics["failed_steps"] == 0
        (port,) = metrics["ports"].values()
        assert port["force_max_n"] == metrics["port_force_max_n"]
        # the spring part is k x displacement (docs/design.md 17.2); the check counted
        assert metrics["port_force_spring_max_n"] == pytest.approx(
            2000.0 * metrics["port_displacement_max_m"], rel=1e-12)
        assert port["spring_force_max_n"] == metrics["port_force_spring_max_n"]
        assert metrics["port_force_peak_spring_n"] + metrics["port_force_peak_damper_n"] \
            >= metrics["port_force_max_n"] - 1e-12  # |a + b| <= |a| + |b|
        assert isinstance(metrics["interface_faults"], int)
    assert plant["settings"]["interface_limits"] == "count"
    report = (out / "report.html").read_text()
    assert "payload 0.5 kg" in report and "abdominal wall 2 N/mm" in report
    assert "port force max (N)" in report and "port_force.png" in report
    assert (out / "port_force.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    csv_header = (out / "metrics.csv").read_text().splitlines()[0]
    assert csv_header.endswith("joint_jerk_rms_radps3,ee_velocity_power_above_3hz,"
                               "port_force_spring_max_n,port_force_damper_max_n,"
                               "port_force_peak_spring_n,port_force_peak_damper_n,"
                               "interface_faults,interface_first_fault_t_s")
    assert "MuJoCo plant at 2000 Hz" in run.stdout and "port force max (N)" in run.stdout


def test_acceleration_limits_from_the_command_line_bound_every_command(tmp_path):
    """``--acceleration-limits``: recorded in metrics.json, and the commanded joint
    accelerations the run measured stay within the robot's limits (the jerk metric's
    first difference, from the commands themselves, in the test)."""
    from teleop import load_robot
    from teleop.experiments.compare import run_plan
    from teleop.experiments.scenarios import load_scenario

    out = tmp_path / "out"
    run = teleop("compare", "--scenario", "fast-lateral", "--controllers", "cjm,qp:daqp",
                 "--duration", "0.6", "--acceleration-limits", "--out", str(out), "--quiet",
                 "--no-plots")
    assert run.returncode == 0, run.stderr
    document = json.loads((out / "metrics.json").read_text())
    jsonschema.validate(document, SCHEMA)
    assert document["acceleration_limits"] is True and "acceleration limits" in run.stdout
    robot = load_robot("sda10f")
    for limits in (False, True):
        result = run_plan(load_scenario("fast-lateral", robot), "qp:daqp", duration=0.6,
                          acceleration_limits=limits)
        commands = np.vstack([np.zeros(robot.nv), result.commanded_joint_velocity])
        acceleration = np.abs(np.diff(commands, axis=0)) / 1e-3
        worst = float(np.max(acceleration / robot.acceleration_limit))
        if limits:
            assert worst <= 1 + 1e-9, worst
        else:
            assert worst > 1.5, worst  # the scenario needs them: without, they are exceeded


def test_a_session_records_its_plant_and_a_replay_runs_on_it(tmp_path):
    session = tmp_path / "s.jsonl"
    run = teleop("record", "--scenario", "trocar-circle", "--duration", "0.1", "--plant",
                 "mujoco", "--payload", "0.2", "--wall-stiffness", "3", str(session))
    assert run.returncode == 0, run.stderr
    recorded = session_plant(load_session(session))
    assert recorded == PlantChoice("mujoco", PlantSettings(payload=0.2), 3000.0)
    added = [json.loads(line) for line in session.read_text().splitlines()
             if '"add"' in line]
    assert [event["constraint"]["tissue_stiffness"] for event in added] == [3000.0]

    out = tmp_path / "replayed"
    run = teleop("replay", str(session), "--controllers", "cjm", "--out", str(out),
                 "--no-plots", "--quiet", "--servo-bandwidth", "30")
    assert run.returncode == 0, run.stderr
    document = json.loads((out / "metrics.json").read_text())
    jsonschema.validate(document, SCHEMA)
    settings_used = document["plant"]["settings"]
    assert document["plant"]["kind"] == "mujoco" and settings_used["payload_kg"] == 0.2
    assert settings_used["servo_bandwidth_hz"] == 30.0  # the option over the header
    assert document["controllers"]["cjm"]["port_force_max_n"] > 0

    out = tmp_path / "kinematic"
    run = teleop("replay", str(session), "--controllers", "cjm", "--out", str(out),
                 "--no-plots", "--quiet", "--plant", "kinematic")
    assert run.returncode == 0, run.stderr
    document = json.loads((out / "metrics.json").read_text())
    assert document["plant"] == {"kind": "kinematic", "settings": None,
                                 "wall_stiffness_n_per_m": 3000.0}
    assert document["controllers"]["cjm"]["port_force_max_n"] is None


def test_a_session_without_a_plant_replays_on_the_kinematic_plant(tmp_path):
    session = tmp_path / "s.jsonl"
    assert teleop("record", "--scenario", "paper-hole", "--duration", "0.05",
                  str(session)).returncode == 0
    header, *events = session.read_text().splitlines()
    header = json.loads(header)
    assert header.pop("plant") == PlantChoice().to_dict()  # written, the default
    session.write_text("\n".join([json.dumps(header), *events]) + "\n")  # as before it was
    assert session_plant(load_session(session)) == PlantChoice()
    out = tmp_path / "out"
    run = teleop("replay", str(session), "--controllers", "cjm", "--out", str(out),
                 "--no-plots", "--quiet")
    assert run.returncode == 0, run.stderr
    assert json.loads((out / "metrics.json").read_text())["plant"]["kind"] == "kinematic"


def test_the_bench_times_the_plant_and_the_kinematic_tick_in_one_run():
    timings = run_bench(["ur5_instrument"], ["cjm", "qp:daqp"], iterations=20, plant=MUJOCO)
    for timing in timings:
        assert timing.plant == "mujoco"
        # the plant's tick holds the step too: it costs more than the step alone
        assert timing.kinematic_tick_median_us > 0 and timing.plant_tick_median_us > 0
    table = format_table(timings)
    assert "mujoco tick us" in table and "kinematic tick us" in table
    plain = run_bench(["ur5_instrument"], ["cjm"], iterations=5)
    assert plain[0].plant_tick_median_us == 0.0 and "tick us" not in format_table(plain)


@pytest.mark.parametrize("kwargs, pattern", [
    ({"kind": "rigid"}, r"plant must be one of kinematic, mujoco, ros2, got 'rigid'"),
    ({"settings": PlantSettings(payload=1.0)}, r"payload_kg need the mujoco plant"),
    ({"kind": "mujoco", "settings": {"payload": 1}}, r"plant settings must be PlantSettings"),
    ({"wall_stiffness": -1.0}, r"wall_stiffness must be >= 0"),
    ({"wall_stiffness": float("nan")}, r"wall_stiffness must be finite"),
])
def test_a_bad_plant_choice_names_the_field(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        PlantChoice(**kwargs)


def test_the_wall_stiffness_reaches_every_hole_and_nothing_else():
    plan = load_scenario("barrier")  # a hole and a barrier
    constraints = plan.make_constraints()
    PlantChoice(wall_stiffness=1234.0).apply_wall(constraints)
    assert [getattr(c, "tissue_stiffness", None) for c in constraints] == [1234.0, None]
    assert PlantChoice.from_dict(PlantChoice("mujoco", PlantSettings(payload=0.3),
                                             10.0).to_dict()) \
        == PlantChoice("mujoco", PlantSettings(payload=0.3), 10.0)
    # the fast-lateral target moves its tip sideways at 0.2 m/s at most
    fast = load_scenario("fast-lateral")
    dt = 1e-4
    positions = np.array([fast.target(k * dt).translation for k in range(int(fast.duration / dt))])
    speed = np.linalg.norm(np.diff(positions, axis=0), axis=1) / dt
    assert np.max(speed) == pytest.approx(0.2, rel=1e-3)
    assert np.allclose(fast.target(fast.duration).translation, fast.target(0.0).translation,
                       atol=1e-12)
