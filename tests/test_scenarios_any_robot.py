"""Item 2 of issue 38: any robot in every command. example-robot-data's Panda and UR5
run the portable scenarios (the hole halfway along the given link, the paths scaled by
the arm's reach), their gripper joints locked by default, and ``teleop robots`` names
their URDFs."""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from teleop.cli.main import main
from teleop.cli.robot_options import add_robot_arguments, robot_from_arguments
from teleop.experiments.compare import compare
from teleop.experiments.placement import placement
from teleop.experiments.scenarios import PORTABLE_SCENARIOS, load_scenario
from teleop.robots import load_robot

#: example-robot-data's URDFs, found from Pinocchio's install (the cmeel prefix both share),
#: not through teleop.robots.catalog
ROBOTS = Path(pin.__file__).resolve().parents[4] / "share/example-robot-data/robots"
PANDA = ROBOTS / "panda_description/urdf/panda.urdf"
UR5 = ROBOTS / "ur_description/urdf/ur5_robot.urdf"

#: (options, the hole's distance along the link from the URDF: half the link's run to
#: what follows it on the way to the EE)
ARMS = {
    # panda_joint8 0.107 along z of link 7, panda_hand_tcp 0.1034 beyond it
    "panda": (["--robot", str(PANDA), "--ee-frame", "panda_hand_tcp",
               "--constrained-link", "panda_link7"], 0.5 * (0.107 + 0.1034)),
    # wrist_1_joint 0.39225 along z of the forearm
    "ur5": (["--robot", str(UR5), "--ee-frame", "tool0", "--constrained-link", "forearm_link"],
            0.5 * 0.39225),
}


def arm(name: str, *extra: str):
    parser = argparse.ArgumentParser()
    add_robot_arguments(parser, "sda10f")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a mesh that cannot be read: not needed here
        return robot_from_arguments(parser.parse_args([*ARMS[name][0], *extra]), "sda10f")


def test_the_pandas_fingers_are_locked_unless_told_otherwise():
    locked = arm("panda")
    assert locked.nq == 7 and set(locked.locked_joints) == {"panda_finger_joint1",
                                                            "panda_finger_joint2"}
    assert arm("panda", "--locked-joints", "none").nq == 9
    assert set(arm("panda", "--locked-joints", "panda_finger_joint1").locked_joints) == {
        "panda_finger_joint1"}
    assert arm("ur5").nq == 6 and not arm("ur5").locked_joints


@pytest.mark.parametrize("name", sorted(ARMS))
def test_the_hole_sits_halfway_along_the_link_at_home(name):
    robot = arm(name)
    distance = ARMS[name][1]
    assert placement(robot, "ur5_instrument", 0.2).hole_distance == pytest.approx(distance,
                                                                                  abs=1e-12)
    hole = load_scenario("trocar-circle", robot).make_constraints()[0]
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_home)
    link = data.oMf[robot.model.getFrameId(robot.constrained_link)]
    expected = link.act(np.array([0.0, 0.0, distance]))  # both links' axis: z
    np.testing.assert_allclose(hole.center, expected, rtol=0, atol=1e-12)


def test_the_built_in_robots_keep_their_own_numbers():
    assert placement(load_robot("ur5_instrument"), "ur5_instrument", 0.2).scale == 1.0
    assert placement(load_robot("sda10f"), "sda10f", 0.08).hole_distance == 0.08


@pytest.mark.parametrize("name", sorted(ARMS))
def test_trocar_circle_runs_without_a_failed_cjm_step_and_the_qp_holds_the_same_hole(name):
    results = compare(load_scenario("trocar-circle", arm(name)), ["cjm", "qp:daqp"],
                      progress=False, agreement=False)
    cjm, qp = (results[spec].metrics() for spec in ("cjm", "qp:daqp"))
    assert cjm["failed_steps"] == 0 and qp["failed_steps"] == 0
    assert cjm["hole_error_max_m"] < 1e-6  # the supervisor's "ok" is 0.1 mm
    assert cjm["hole_error_max_m"] == pytest.approx(qp["hole_error_max_m"], rel=1e-3)


@pytest.mark.parametrize("scenario", sorted(set(PORTABLE_SCENARIOS) - {"trocar-circle"}))
@pytest.mark.parametrize("name", sorted(ARMS))
def test_the_other_portable_scenarios_run_without_a_failed_cjm_step(name, scenario):
    (result,) = compare(load_scenario(scenario, arm(name)), ["cjm"], progress=False).values()
    metrics = result.metrics()
    assert metrics["failed_steps"] == 0 and metrics["hole_error_max_m"] < 1e-5
    assert metrics["joint_limit_violation_max_rad"] == 0.0


def test_a_scenario_written_for_one_robot_names_those_that_move(capsys):
    with pytest.raises(ValueError, match="runs on sda10f_dual only; on another robot: paper-hole"):
        load_scenario("bimanual-trocars", arm("panda"))


def test_compare_takes_the_robot_options(tmp_path, capsys):
    assert main(["compare", *ARMS["panda"][0], "--scenario", "trocar-circle", "--duration", "0.5",
                 "--controllers", "cjm", "--no-plots", "--quiet", "--out", str(tmp_path)]) == 0
    document = json.loads((tmp_path / "metrics.json").read_text())
    assert document["robot"] == "panda" and document["controllers"]["cjm"]["failed_steps"] == 0
    assert "hole 10.5 cm along panda_link7" in document["description"]


def test_robots_lists_the_built_ins_and_the_installed_urdfs(capsys):
    assert main(["robots"]) == 0
    out = capsys.readouterr().out
    assert "sda10f " in out and "ur5_instrument" in out
    assert "panda_description/urdf/panda.urdf" in out and "ur5_robot " in out


def test_a_sweep_runs_its_cells_on_the_robot_of_its_spec():
    from teleop.experiments.sweep import build_spec, compare_command, run_cell

    robot = {"robot": str(PANDA), "ee_frame": "panda_hand_tcp", "constrained_link": "panda_link7"}
    spec = build_spec({"scenarios": "trocar-circle", "controllers": "cjm", "duration": 0.2,
                       "robot": robot})
    (cell,) = spec.cells()
    assert cell.inputs["robot"] == robot
    outcome = run_cell(cell.inputs, 600.0)
    assert outcome["status"] == "done" and outcome["metrics"]["failed_steps"] == 0
    assert (f"--robot {PANDA} --ee-frame panda_hand_tcp --constrained-link panda_link7"
            in compare_command(cell.inputs))
    with pytest.raises(ValueError, match="robot: unknown key 'arm'"):
        build_spec({"scenarios": "trocar-circle", "controllers": "cjm", "robot": {"arm": "x"}})
