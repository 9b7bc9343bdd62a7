"""Collision avoidance in the experiments (docs/design.md 18.6): the scenarios, the loop's
minimum distance against an independent computation, the CLI's options, sessions, and the
physics plant's contacts against MuJoCo's own contact list."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import jsonschema
import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from constraints import Hole
from constraints.collision import CollisionAvoidance, Sphere
from teleop.cli.main import main
from teleop.controller_specs import make_controller
from teleop.experiments.compare import compare, metrics_document
from teleop.experiments.scenarios import load_scenario
from teleop.experiments.sessions import (SessionError, load_session, record_plan,
                                         session_plan)
from teleop.loop import SAFETY_TOLERANCE, DistanceMeter, LoopConfig, TeleopLoop
from teleop.plants.contact_geometry import OBSTACLE_GEOM, ROBOT_GEOM
from teleop.plants.mujoco_plant import MujocoPlant
from teleop.robots import load_robot

SCHEMA = json.loads((Path(__file__).resolve().parent.parent / "teleop" / "experiments"
                     / "metrics.schema.json").read_text())

#: How far two coal distances of one pair at one q may differ (m): GJK's convergence
#: tolerance (coal's default 1e-6) for a box, warm-started from the previous call or not.
GJK_TOLERANCE = 1e-6

COLLISION_SCENARIOS = ("bimanual-crossing", "obstacle", "mobile-obstacles")
SPECS = ("cjm", "qp:daqp")
#: steps each scenario runs in the tests: until some pair is within the detection distance
#: (the crossing tips meet after 2 s)
TEST_STEPS = {"bimanual-crossing": 2400, "obstacle": 1200, "mobile-obstacles": 1200}


def true_minimum(avoidance: CollisionAvoidance, model: pin.Model, q: np.ndarray) -> float:
    """The smallest distance over every pair at ``q``, no broadphase (coal through
    ``CollisionAvoidance.distances``)."""
    data = model.createData()
    pin.forwardKinematics(model, data, q)
    return min(distance for _, distance in avoidance.distances(model, data))


def drive(plan, spec: str, steps: int) -> tuple[list, list[np.ndarray], TeleopLoop]:
    """``steps`` periods of ``plan`` with ``spec``: the records and the true q after each."""
    constraints = plan.make_constraints()
    controller = make_controller(spec, plan.robot, constraints, time_budget=None,
                                 collisions=plan.make_collisions())
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=LoopConfig(),
                      collisions=plan.make_collisions())
    records, configurations = [], []
    for i in range(steps):
        plan.update(i * 1e-3, constraints, loop.q)
        records.append(loop.tick(plan.target((i + 1) * 1e-3)))
        configurations.append(loop.q.copy())
    return records, configurations, loop


@pytest.mark.parametrize("spec", SPECS)
@pytest.mark.parametrize("name", COLLISION_SCENARIOS)
def test_the_loop_measures_the_true_minimum_distance(name, spec):
    """Every 40th step (:data:`TEST_STEPS`): the recorded minimum equals coal's over every pair
    at the recorded q where it is below the detection distance (the broadphase keeps
    every such pair), and is never below it; the counts are the steps below 0 and
    below d_s - 0.5 mm."""
    plan = load_scenario(name)
    records, configurations, loop = drive(plan, spec, TEST_STEPS[name])
    reference = plan.make_collisions()
    reference.set_ports(loop.constraints)
    detection = reference.detection_distance
    compared = 0
    for record, q in list(zip(records, configurations))[::40]:
        exact = true_minimum(reference, plan.robot.model, q)
        if exact < detection:
            assert record.minimum_distance == pytest.approx(exact, abs=GJK_TOLERANCE)
            compared += 1
        else:
            assert record.minimum_distance >= exact - GJK_TOLERANCE
    assert compared > 0  # every scenario has a pair within reach
    distances = np.array([r.minimum_distance for r in records])
    assert loop.distance_meter.penetrations == int(np.sum(distances < 0.0))
    assert loop.distance_meter.safety_violations == int(np.sum(
        distances < reference.safety_distance - SAFETY_TOLERANCE))


@pytest.mark.parametrize("spec", SPECS)
@pytest.mark.parametrize("name", COLLISION_SCENARIOS)
def test_the_scenarios_keep_every_pair_apart(name, spec):
    """Zero penetrations and every distance at or above d_s - 0.5 mm (issue 21's target)."""
    plan = load_scenario(name)
    results = compare(plan, [spec], duration=TEST_STEPS[name] * 1e-3, progress=False,
                      agreement=False)
    metrics = results[spec].metrics()
    safety = plan.collisions["safety_distance"]
    assert metrics["penetration_steps"] == 0
    assert metrics["safety_violation_steps"] == 0
    assert metrics["minimum_distance_m"] >= safety - SAFETY_TOLERANCE


@functools.cache
def dual_robot():
    return load_robot("sda10f_dual")


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=15, max_size=15))
def test_the_meter_is_exact_below_the_detection_distance(fractions):
    """At configurations drawn across the joint ranges of sda10f_dual, with an obstacle
    at the left tip: the meter's minimum equals coal's over every pair when it is below
    d_i, and is an upper bound otherwise."""
    robot = dual_robot()
    model = robot.model
    middle = 0.5 * (model.upperPositionLimit + model.lowerPositionLimit)
    half = 0.5 * (model.upperPositionLimit - model.lowerPositionLimit)
    q = middle + 0.5 * np.asarray(fractions) * half
    data = model.createData()
    pin.framesForwardKinematics(model, data, robot.q_home)
    tip = data.oMf[model.getFrameId(robot.ee_frames[0])].translation
    avoidance = CollisionAvoidance(robot, [Sphere(tip, 0.05)])
    meter = DistanceMeter(avoidance)
    measured = meter.measure(model, model.createData(), q)
    exact = true_minimum(CollisionAvoidance.from_dict(robot, avoidance.to_dict()), model, q)
    if exact < avoidance.detection_distance:
        assert measured.minimum_distance == pytest.approx(exact, abs=GJK_TOLERANCE)
    else:
        assert measured.minimum_distance >= exact - GJK_TOLERANCE
    assert meter.penetrations == int(measured.minimum_distance < 0.0)


def test_existing_scenarios_declare_no_collision_avoidance():
    for name in ("paper-hole", "bimanual-trocars", "mobile-wall", "fast-lateral"):
        assert load_scenario(name).collisions is None
    for name in COLLISION_SCENARIOS:
        plan = load_scenario(name)
        assert plan.collisions is not None
        assert plan.make_collisions() is not plan.make_collisions()  # fresh per run


def test_compare_writes_the_collision_metrics(tmp_path):
    code = main(["compare", "--scenario", "obstacle", "--controllers", "cjm", "--duration",
                 "0.05", "--out", str(tmp_path), "--quiet", "--safety-distance", "8"])
    assert code == 0
    document = json.loads((tmp_path / "metrics.json").read_text())
    jsonschema.validate(document, SCHEMA)
    assert document["schema_version"] == 9
    assert document["collisions"]["safety_distance"] == pytest.approx(0.008)
    assert [o["name"] for o in document["collisions"]["obstacles"]] == ["organ"]
    metrics = document["controllers"]["cjm"]
    plan = load_scenario("obstacle")
    records, configurations, _ = drive(plan, "cjm", 50)
    assert metrics["minimum_distance_m"] == pytest.approx(
        min(r.minimum_distance for r in records), abs=1e-9)
    assert metrics["closest_pair"] == "arm_link_7_t | organ"
    assert metrics["contact_steps"] is None  # the kinematic plant has no body
    assert (tmp_path / "minimum_distance.png").is_file()
    assert "Collision avoidance" in (tmp_path / "report.html").read_text()


def test_no_collisions_and_collisions_override_the_scenario(tmp_path):
    assert main(["compare", "--scenario", "obstacle", "--controllers", "cjm", "--duration",
                 "0.01", "--out", str(tmp_path / "off"), "--quiet", "--no-plots",
                 "--no-collisions"]) == 0
    document = json.loads((tmp_path / "off" / "metrics.json").read_text())
    jsonschema.validate(document, SCHEMA)
    assert document["collisions"] is None
    assert document["controllers"]["cjm"]["minimum_distance_m"] is None
    assert main(["compare", "--scenario", "paper-hole", "--controllers", "cjm", "--duration",
                 "0.01", "--out", str(tmp_path / "on"), "--quiet", "--no-plots",
                 "--collisions"]) == 0
    document = json.loads((tmp_path / "on" / "metrics.json").read_text())
    jsonschema.validate(document, SCHEMA)
    assert document["collisions"]["obstacles"] == []
    assert document["collisions"]["self_collision"] is True
    plan = load_scenario("paper-hole")
    avoidance = CollisionAvoidance(plan.robot)
    exact = true_minimum(avoidance, plan.robot.model, plan.q0)
    measured = document["controllers"]["cjm"]["minimum_distance_m"]
    # 10 ms of slow motion moves the self-collision minimum by well under a millimetre:
    # exact below d_i, else an upper bound or nothing measured (null)
    if exact < avoidance.detection_distance - 1e-3:
        assert measured == pytest.approx(exact, abs=1e-3)
    else:
        assert measured is None or measured >= exact - 1e-3
    assert document["controllers"]["cjm"]["penetration_steps"] == 0


def exit_code(argv: list[str]) -> int:
    """``teleop`` run in-process: its exit code (argparse's errors exit, the rest return)."""
    try:
        return main(argv)
    except SystemExit as stop:
        return int(stop.code)


@pytest.mark.parametrize("arguments, message", [
    (["--safety-distance", "60"], "detection_distance"),
    (["--detection-distance", "2"], "detection_distance"),
    (["--no-collisions", "--approach-speed", "0.2"], "needs collision avoidance"),
    (["--safety-distance", "-1"], "must be in [0, 1000] mm"),
    (["--approach-speed", "0"], "must be in (0, 10] m/s"),
    (["--approach-speed", "nan"], "must be in (0, 10] m/s"),
    (["--collisions", "--no-collisions"], "not allowed with"),
])
def test_bad_collision_options_are_one_line_and_exit_2(arguments, message, tmp_path, capsys):
    code = exit_code(["compare", "--scenario", "obstacle", "--controllers", "cjm", "--duration",
                      "0.01", "--out", str(tmp_path), "--quiet", *arguments])
    error = capsys.readouterr().err
    assert code == 2
    assert message in error and error.count("\n") == 1


def test_sessions_round_trip_the_collision_avoidance(tmp_path):
    plan = load_scenario("obstacle")
    path = record_plan(plan, tmp_path / "s.jsonl", duration=0.05)
    header = json.loads(path.read_text().splitlines()[0])
    # 3 brought the collisions, 4 the input devices' lines, 5 the task modes
    assert header["version"] == 5
    replayed = session_plan(load_session(path))
    assert replayed.collisions == plan.collisions
    obstacle = replayed.make_collisions().obstacles[0]
    assert obstacle.to_dict() == plan.make_collisions().obstacles[0].to_dict()
    # the replay measures what the scenario does
    direct, _, _ = drive(plan, "cjm", 50)
    again, _, _ = drive(replayed, "cjm", 50)
    np.testing.assert_allclose([r.minimum_distance for r in again],
                               [r.minimum_distance for r in direct], atol=1e-9)


@pytest.mark.parametrize("change, message", [
    (lambda h: h["collisions"].update(safety_distance=-1.0), "safety_distance"),
    (lambda h: h["collisions"]["obstacles"][0].update(radius="big"), "radius"),
    (lambda h: h["collisions"].update(colour=1), "unknown collision field"),
    (lambda h: h.update(collisions=[1]), "'collisions' must be an object"),
    (lambda h: h.update(version=2), "needs version 3"),
])
def test_bad_collisions_in_a_session_name_the_file_and_line(change, message, tmp_path):
    path = record_plan(load_scenario("obstacle"), tmp_path / "s.jsonl", duration=0.01)
    lines = path.read_text().splitlines()
    header = json.loads(lines[0])
    change(header)
    path.write_text("\n".join([json.dumps(header), *lines[1:]]) + "\n")
    with pytest.raises(SessionError, match=rf"s\.jsonl:1: .*{message}"):
        session_plan(load_session(path))


def test_the_plant_counts_mujocos_contacts():
    """A sphere around the tip and the two arms' tools pushed into each other: the plant's
    contact count is MuJoCo's contact list filtered by hand (robot-obstacle and robot-robot
    contacts of the avoidance's link pairs), its depth the deepest of them."""
    robot = load_robot("sda10f")
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, robot.q_home)
    tip = data.oMf[model.getFrameId(robot.ee_frame)].translation
    avoidance = CollisionAvoidance(robot, [Sphere(tip + [0.0, 0.0, -0.04], 0.02, name="organ")])
    plant = MujocoPlant(robot, 1e-3, collisions=avoidance)
    plant.actuate(np.zeros(model.nv), robot.q_home)
    mj_model, mj_data = plant.mj_model, plant.mj_data
    pairs = {frozenset(pair) for pair in avoidance.pairs}
    links = {item.name: model.frames[item.parentFrame].name
             for item in robot.collision_model.geometryObjects}

    def owner(geom: int) -> str:
        name = mj_model.geom(geom).name
        if name.startswith(OBSTACLE_GEOM):
            return name[len(OBSTACLE_GEOM):]
        return links[name[len(ROBOT_GEOM):]]

    counted = [c for c in mj_data.contact[:mj_data.ncon]
               if frozenset((owner(c.geom1), owner(c.geom2))) in pairs and c.dist < 0.0]
    measures = plant.measures()
    assert measures.contacts == len(counted) == mj_data.ncon
    assert measures.contacts > 0
    assert measures.contact_depth == pytest.approx(max(-c.dist for c in counted))
    # coal agrees the tool is inside the organ by about that depth
    exact = true_minimum(CollisionAvoidance.from_dict(robot, avoidance.to_dict()), model,
                         robot.q_home)
    assert exact < 0.0
    assert measures.contact_depth == pytest.approx(-exact, abs=2e-3)


def test_a_port_placed_on_the_plant_switches_off_the_instruments_contacts():
    """An organ around a trocar, placed after the plant is built: the instrument inside it
    stops touching the organ in the simulation as it stops being kept away from it by
    the avoidance. The contacts left are those of the pairs a fresh avoidance with the port
    checks (the reference), and the contacts come back when the port goes."""
    robot = load_robot("sda10f")
    model = robot.model
    hole = Hole.on_link(robot, robot.q_home, distance=0.08)
    organ = Sphere(hole.position, 0.03, name="organ")
    plant = MujocoPlant(robot, 1e-3, collisions=CollisionAvoidance(robot, [organ]))
    links = {item.name: model.frames[item.parentFrame].name
             for item in robot.collision_model.geometryObjects}
    mj_model = plant.mj_model

    def owners(contact) -> frozenset[str]:
        names = [mj_model.geom(g).name for g in (contact.geom1, contact.geom2)]
        return frozenset(name[len(OBSTACLE_GEOM):] if name.startswith(OBSTACLE_GEOM)
                         else links[name[len(ROBOT_GEOM):]] for name in names)

    def touching(constraints) -> set[frozenset[str]]:
        plant.reset(robot.q_home)
        plant.actuate(np.zeros(model.nv), robot.q_home, constraints)
        data = plant.mj_data
        assert plant.measures().contacts == data.ncon
        return {owners(contact) for contact in data.contact[:data.ncon]}

    reference = CollisionAvoidance(robot, [organ])
    before = {frozenset(pair) for pair in reference.pairs}
    reference.set_ports([hole])
    exempt = before - {frozenset(pair) for pair in reference.pairs}
    without_port = touching([])
    assert without_port & exempt  # the instrument is inside the organ
    with_port = touching([hole])
    assert not with_port & exempt
    assert with_port == without_port - exempt
    assert {frozenset(pair) for pair in plant.contact_pairs.switched_off} == exempt
    assert touching([]) == without_port


def test_the_plant_without_collision_avoidance_has_no_geometry():
    robot = load_robot("sda10f")
    plant = MujocoPlant(robot, 1e-3)
    assert plant.mj_model.ngeom == 0 and plant.mj_model.npair == 0
    plant.actuate(np.zeros(robot.model.nv), robot.q_home)
    assert plant.measures().contacts == 0 and plant.measures().contact_depth == 0.0


def test_compare_on_the_physics_plant_reports_contacts():
    from teleop.plants.choice import PlantChoice

    plan = load_scenario("obstacle")
    plant = PlantChoice("mujoco")
    results = compare(plan, ["cjm"], duration=0.05, progress=False, agreement=False,
                      plant=plant)
    document = metrics_document(plan, results, LoopConfig(), 0.05, plant=plant)
    jsonschema.validate(json.loads(json.dumps(document)), SCHEMA)
    metrics = document["controllers"]["cjm"]
    assert metrics["contact_steps"] == 0  # 2 cm apart, 50 ms of slow motion
    assert metrics["contact_depth_max_m"] == 0.0


def test_the_damper_options_state_the_avoidance_defaults():
    """The CLIs' help (written without importing coal, to stay fast) says the defaults
    CollisionAvoidance has."""
    from constraints.collision import (DEFAULT_APPROACH_SPEED, DEFAULT_DETECTION_DISTANCE,
                                       DEFAULT_SAFETY_DISTANCE)
    from teleop.cli.arguments import DAMPER_OPTIONS

    defaults = {"safety_distance": 1e3 * DEFAULT_SAFETY_DISTANCE,
                "detection_distance": 1e3 * DEFAULT_DETECTION_DISTANCE,
                "approach_speed": DEFAULT_APPROACH_SPEED}
    for _, name, _, help_text in DAMPER_OPTIONS:
        assert f"(default: {defaults[name]:g})" in help_text
