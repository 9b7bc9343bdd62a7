"""The collision damper counts on the robot's response time (docs/design.md 18.3, 18.6):
its rate ``1 / K = (d_i - d_s) / xi + tau`` in every controller's rows, the physics plant's
``tau`` (its servos' time constant) given by a comparison, and on the plant a stiff damper
(``xi`` = 10 m/s) on 20 Hz servos carrying 2 kg keeps the crossing arms at least
``d_s - 0.5 mm`` apart, where the damper that ignores the servos does not."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import jsonschema
import numpy as np
import pinocchio as pin
import pytest

from constraints.collision import CollisionAvoidance
from teleop.controller_specs import make_controller
from teleop.experiments.compare import compare, metrics_document
from teleop.experiments.scenarios import load_scenario
from teleop.loop import LoopConfig, TeleopLoop
from teleop.plants.choice import PlantChoice
from teleop.plants.settings import PlantSettings

SCHEMA = json.loads((Path(__file__).resolve().parent.parent / "teleop" / "experiments"
                     / "metrics.schema.json").read_text())

#: the 20 Hz servos' time constant (s), written out
SERVO_TIME_CONSTANT = 1.0 / (2.0 * math.pi * 20.0)


@pytest.fixture(scope="module")
def crossing():
    """``bimanual-crossing`` with the damper at ``xi`` = 10 m/s (``K`` = 222 1/s)."""
    plan = load_scenario("bimanual-crossing")
    return dataclasses.replace(plan, collisions={**plan.collisions, "approach_speed": 10.0})


def close_rows(avoidance: CollisionAvoidance, plan, steps: int = 2230):
    """The rows where the crossing tips are within a few mm (the kinematic run's ``q``
    after ``steps`` periods under the CJM)."""
    constraints = plan.make_constraints()
    controller = make_controller("cjm", plan.robot, constraints, time_budget=None,
                                 collisions=plan.make_collisions())
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=LoopConfig())
    for i in range(steps):
        loop.tick(plan.target((i + 1) * 1e-3))
    model, data = plan.robot.model, plan.robot.model.createData()
    pin.computeJointJacobians(model, data, loop.q)
    return avoidance.rows(model, data), loop.q


def test_the_rate_is_the_damper_and_the_response_in_series(crossing):
    """Every pair's bound holds the gap ``tau`` ahead along the rate it allows,
    ``d_dot >= -(xi / (d_i - d_s)) (d - d_s + tau d_dot)``; the rows themselves are the
    damper's without a response time."""
    settings = crossing.collisions
    plain = CollisionAvoidance.from_dict(crossing.robot, settings)
    late = CollisionAvoidance.from_dict(crossing.robot, {**settings, "response_time": 0.008})
    d_s, d_i, xi = 0.005, 0.05, 10.0
    assert plain.gain == xi / (d_i - d_s)
    assert late.gain == pytest.approx(1.0 / ((d_i - d_s) / xi + 0.008), rel=1e-15)
    rows, q = close_rows(late, crossing)
    model, data = crossing.robot.model, crossing.robot.model.createData()
    pin.computeJointJacobians(model, data, q)
    again = plain.rows(model, data)
    assert rows.size >= 1 and rows.pairs == again.pairs
    np.testing.assert_array_equal(rows.rows, again.rows)
    np.testing.assert_array_equal(rows.distances, again.distances)
    gap = rows.distances - d_s
    held_ahead = -(xi / (d_i - d_s)) * (gap + 0.008 * rows.lower)
    np.testing.assert_allclose(rows.lower, held_ahead, rtol=1e-12, atol=1e-18)
    assert np.all(np.abs(rows.lower) < np.abs(again.lower))  # closing or pushed out: slower


def test_every_controller_brakes_at_the_lower_rate(crossing):
    """The compiled CJM, the Python CJM, the QP and mink hold the same rate: each one's
    command at a close configuration keeps ``d_dot >= -K (d - d_s)`` with ``K`` the
    series rate, and reaches it (the tips pushed together at 0.3 m/s each)."""
    late = {**crossing.collisions, "response_time": 0.008}
    avoidance = CollisionAvoidance.from_dict(crossing.robot, late)
    rows, q = close_rows(avoidance, crossing)
    twist = np.zeros(12)
    model, data = crossing.robot.model, crossing.robot.model.createData()
    pin.framesForwardKinematics(model, data, q)
    tips = [data.oMf[frame] for frame in crossing.robot.ee_frame_ids]
    for k, (tip, other) in enumerate(zip(tips, tips[::-1])):
        towards = other.translation - tip.translation
        twist[6 * k:6 * k + 3] = tip.rotation.T @ (0.3 * towards / np.linalg.norm(towards))
    for spec in ("cjm", "cjm:python", "qp:daqp", "mink:daqp"):
        controller = make_controller(spec, crossing.robot, crossing.make_constraints(),
                                     time_budget=None,
                                     collisions=CollisionAvoidance.from_dict(crossing.robot,
                                                                             late))
        qd = controller.solve(q, twist)
        rates = rows.rows @ qd
        assert np.all(rates >= rows.lower - 1e-7), (spec, rates, rows.lower)
        assert np.min(rates - rows.lower) <= 1e-6, (spec, rates, rows.lower)


def test_a_comparison_on_the_plant_counts_on_its_servos(crossing):
    plant = PlantChoice("mujoco", PlantSettings(payload=2.0))
    assert plant.response_time == pytest.approx(SERVO_TIME_CONSTANT, rel=1e-15)
    assert PlantChoice().response_time == 0.0
    results = compare(crossing, ["cjm"], duration=0.01, progress=False, agreement=False,
                      plant=plant)
    document = metrics_document(crossing, results, LoopConfig(), 0.01, plant=plant)
    jsonschema.validate(json.loads(json.dumps(document)), SCHEMA)
    assert document["collisions"]["response_time"] == pytest.approx(SERVO_TIME_CONSTANT)
    kinematic = metrics_document(crossing, results, LoopConfig(), 0.01)
    assert "response_time" not in kinematic["collisions"]


def crossing_on_the_plant(plan, response_time: float, steps: int = 2350) -> float:
    """The smallest true distance (m) over ``steps`` periods of ``plan`` under the CJM on
    the physics plant (20 Hz servos, 2 kg at each tip), the damper counting on
    ``response_time``."""
    collisions = {**plan.collisions, "response_time": response_time} if response_time \
        else plan.collisions
    constraints = plan.make_constraints()
    controller = make_controller("cjm", plan.robot, constraints, time_budget=None,
                                 acceleration_limit="robot",
                                 collisions=CollisionAvoidance.from_dict(plan.robot, collisions))
    plant = PlantChoice("mujoco", PlantSettings(payload=2.0))
    loop = TeleopLoop(plan.robot, controller, q0=plan.q0, config=LoopConfig(),
                      plant=plant.make(plan.robot, 1e-3, None, plan.make_collisions()),
                      collisions=plan.make_collisions())
    smallest = np.inf
    for i in range(steps):
        record = loop.tick(plan.target((i + 1) * 1e-3))
        smallest = min(smallest, record.minimum_distance)
    return smallest


def test_the_crossing_arms_stay_apart_on_slow_servos(crossing):
    """The arms meet after 2.2 s; the damper that ignores the servos lets them 4.48 mm
    apart (the robot follows its braking command late, and the stiff damper's loop rings),
    the one counting on their time constant keeps them above d_s - 0.5 mm."""
    bound = crossing.collisions["safety_distance"] - 0.5e-3
    assert crossing_on_the_plant(crossing, 0.0) < bound
    assert crossing_on_the_plant(crossing, SERVO_TIME_CONSTANT) >= bound
