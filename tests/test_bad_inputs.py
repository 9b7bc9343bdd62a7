"""Every bad input is one line naming the field: a ``ValueError`` from the Python API, the
file and line for a session file, one line on standard error and exit code 2 at the CLI;
never a traceback, a NaN or a run without end.

Each table row is one input through its public entry point; the rows stand for the
classes of input around them (wrong type, null, out of range, beyond the documented maxima
of :mod:`teleop.limits`, nested without end).
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from functools import cache

import numpy as np
import pytest

from constraints import Barrier, Hole, Plane, PointLock
from controllers import CJMController
from teleop import load_robot
from teleop.cli.main import main as teleop_main
from teleop.controller_specs import make_controller
from teleop.experiments.bench import run_bench
from teleop.experiments.compare import compare, run_plan
from teleop.plants.imperfect import Imperfections
from teleop.experiments.scenarios import load_scenario
from teleop.experiments.sessions import SessionError, load_session, record_plan, session_plan
from teleop.loop import LoopConfig, TeleopLoop
from web.scene import parse_scene, read_scene_file, robot_from_dict

ROBOT = "ur5_instrument"
#: nested deeper than Python's recursion limit: json.loads raises RecursionError on it
DEEP = "[" * 100_000 + "]" * 100_000


@cache
def robot():
    return load_robot(ROBOT)


@cache
def plan():
    return load_scenario("paper-hole")


def hole(gain: float = 100.0) -> Hole:
    return Hole.on_link(robot(), robot().q_home, 0.08, gain=gain)


def solve(q=None, twist=None):
    controller = CJMController(robot(), [hole()])
    return controller.solve(robot().q_home if q is None else q,
                            np.full(6, 0.01) if twist is None else twist)


def set_gain(constraint, gain) -> None:
    constraint.gain = gain


def unstable_gain_then_step():
    constraint = hole()
    controller = CJMController(robot(), [constraint])
    constraint.gain = 5000.0  # K dt = 5 at 1 kHz
    controller.solve(robot().q_home, np.zeros(6))


def assert_one_line(message: str, pattern: str) -> None:
    assert "\n" not in message.strip(), message
    assert "Traceback" not in message, message
    assert re.search(pattern, message), (pattern, message)


# ----------------------------------------------------------------------------- the API

API = [
    ("hole.gain=-500", lambda tmp: set_gain(hole(), -500), r"^gain must be >= 0, got -500$"),
    ("hole.gain='abc'", lambda tmp: set_gain(hole(), "abc"), r"^gain must be a number, got 'abc'$"),
    ("hole.gain=nan", lambda tmp: set_gain(hole(), float("nan")), r"^gain must be finite"),
    ("hole.gain=True", lambda tmp: set_gain(hole(), True), r"^gain must be a number, got True"),
    ("hole.gain=10**400", lambda tmp: set_gain(hole(), 10**400), r"^gain must be finite"),
    ("plane.gain=-1", lambda tmp: set_gain(Plane.through_link_point(
        robot(), robot().q_home, [0, 0, 1], distance=0.08), -1), r"^gain must be >= 0"),
    ("barrier.gain=[1]", lambda tmp: set_gain(Barrier.through_link_point(
        robot(), robot().q_home, [0, 0, 1], distance=0.08), [1.0]), r"^gain must be a number"),
    ("plane_point and offset", lambda tmp: Plane.through_link_point(
        robot(), robot().q_home, [0, 0, 1], distance=0.08, plane_point=[0.0, 0.0, 0.5],
        offset=0.01), r"^give plane plane_point or offset, not both"),
    ("point_lock.gain=inf", lambda tmp: set_gain(PointLock.on_link(
        robot(), robot().q_home, distance=0.08), float("inf")), r"^gain must be finite"),
    ("Hole(gain=-500)", lambda tmp: hole(-500.0), r"^gain must be >= 0"),
    ("gain 5000 at 1 kHz, next step", lambda tmp: unstable_gain_then_step(),
     r"^Hole gain 5000 1/s is unstable at 1000 Hz \(K dt = 5, needs < 2\)"),
    ("solve complex twist", lambda tmp: solve(twist=np.full(6, 0.01 + 1e-3j)),
     r"^twist must be an array of 6 numbers"),
    ("solve string twist", lambda tmp: solve(twist=["a"] * 6), r"^twist must be an array of 6"),
    ("solve None twist", lambda tmp: solve(twist=[None] * 6),
     r"^twist must be an array of 6"),
    ("solve bool twist", lambda tmp: solve(twist=[True] * 6), r"^twist must be an array of 6"),
    ("solve nan twist", lambda tmp: solve(twist=[np.nan] * 6), r"^twist must be finite"),
    ("solve short twist", lambda tmp: solve(twist=[0.0] * 5), r"^twist must have shape \(6,\)"),
    ("solve complex q", lambda tmp: solve(q=robot().q_home + 0j), r"^q must be an array of 8 numbers"),
    ("load_robot(None)", lambda tmp: load_robot(None),
     r"^robot must be a built-in robot name or a URDF path, got None"),
    ("load_robot('nope')", lambda tmp: load_robot("nope"), r"^no URDF file at 'nope'"),
    ("load_robot(5)", lambda tmp: load_robot(5), r"^robot must be a built-in robot name"),
    ("load_robot ee_frame list", lambda tmp: load_robot(ROBOT, ee_frame=["tool0"]),
     r"^ee_frame must be a name, got \['tool0'\]"),
    ("make_controller solver_settings='abc'",
     lambda tmp: make_controller("qp:daqp", robot(), solver_settings="abc"),
     r"^solver_settings must be a mapping"),
    ("make_controller solver_settings nan",
     lambda tmp: make_controller("qp:daqp", robot(), solver_settings={"eps": float("nan")}),
     r"^solver_settings\['eps'\] must be finite"),
    ("make_controller spec 5", lambda tmp: make_controller(5, robot()),
     r"^a controller spec must be a string"),
    ("LoopConfig rate 1e12", lambda tmp: LoopConfig(rate=1e12), r"^rate must be <= 10000, got 1e\+12$"),
    ("LoopConfig rate 'abc'", lambda tmp: LoopConfig(rate="abc"), r"^rate must be a number"),
    ("LoopConfig rate 10**400", lambda tmp: LoopConfig(rate=10**400), r"^rate must be finite"),
    ("LoopConfig kp None", lambda tmp: LoopConfig(kp=None), r"^kp must be a number, got None"),
    ("LoopConfig smoothing 1e300", lambda tmp: LoopConfig(target_time_constant=1e300),
     r"^target_time_constant must be <= 1"),
    ("TeleopLoop q0 complex", lambda tmp: TeleopLoop(robot(), CJMController(robot(), []),
                                                     q0=robot().q_home + 1j),
     r"^q0 must be an array of 8 numbers"),
    ("TeleopLoop config 'fast'", lambda tmp: TeleopLoop(robot(), CJMController(robot(), []),
                                                        config="fast"),
     r"^config must be a LoopConfig, got str$"),
    ("encoder noise 1e6", lambda tmp: Imperfections(encoder_noise=1e6),
     r"^encoder_noise must be <= 0.1, got 1e\+06"),
    ("latency 1e9 periods", lambda tmp: Imperfections(latency=10**9),
     r"^latency must be <= 10000 periods"),
    ("joint time constant 'x'", lambda tmp: Imperfections(joint_time_constant="x"),
     r"^joint_time_constant must be a number"),
    ("run_plan duration 1e300", lambda tmp: run_plan(plan(), "cjm", duration=1e300),
     r"^duration must be <= 3600, got 1e\+300"),
    ("run_plan an hour at 10 kHz", lambda tmp: run_plan(plan(), "cjm", LoopConfig(rate=1e4), 3600),
     r"^duration 3600 s at 10000 Hz is 36000000 control periods, more than 1000000"),
    ("run_plan latency 5 s", lambda tmp: run_plan(plan(), "cjm", duration=0.01,
                                                  imperfections=Imperfections(latency=5000)),
     r"^latency must be <= 1 s, got 5000 periods"),
    ("compare latency 5 s", lambda tmp: compare(plan(), ["cjm"], progress=False,
                                                imperfections=Imperfections(latency=5000)),
     r"^latency must be <= 1 s"),
    ("record_plan duration 1e12", lambda tmp: record_plan(plan(), tmp / "s.jsonl", duration=1e12),
     r"^duration must be <= 3600"),
    ("record_plan rate 1e12", lambda tmp: record_plan(plan(), tmp / "s.jsonl", rate_hz=1e12),
     r"^rate_hz must be <= 10000"),
    ("record_plan onto a directory", lambda tmp: record_plan(plan(), tmp, duration=0.01),
     r"^session file '.*' is a directory$"),
    ("run_bench robot 'nope'", lambda tmp: run_bench(["nope"]), r"^unknown robot 'nope'"),
    ("run_bench 1e9 iterations", lambda tmp: run_bench([ROBOT], iterations=10**9),
     r"^iterations must be an integer in \[1, 1000000\]"),
    ("robot_from_dict ee_frame list",
     lambda tmp: robot_from_dict({"source": ROBOT, "ee_frame": ["tool0"]}),
     r"^scene robot.ee_frame must be a name, got \['tool0'\]"),
]


@pytest.mark.parametrize("call, pattern", [pytest.param(call, pattern, id=name)
                                           for name, call, pattern in API])
def test_the_api_raises_one_line_naming_the_field(call, pattern, tmp_path):
    with pytest.raises(ValueError) as error:
        call(tmp_path)
    assert_one_line(str(error.value), pattern)


def test_a_refused_gain_leaves_the_constraint_as_it_was():
    constraint = hole(80.0)
    for bad in (-500, "abc", float("nan"), None):
        with pytest.raises(ValueError):
            constraint.gain = bad
        assert constraint.gain == 80.0


# ----------------------------------------------------------------------------- session files


def session_header(**changes) -> dict:
    header = {"type": "header", "format": "cjm-teleop-session", "version": 2, "robot": ROBOT,
              "q0": robot().q_home.tolist(), "rate_hz": 1000, "kp": 20,
              "target_time_constant_s": 0.05}
    return {**header, **changes}


def session_text(*lines) -> str:
    return "\n".join(line if isinstance(line, str) else json.dumps(line) for line in lines) + "\n"


def hole_added(t: float = 0.0, cid: str = "hole-1", **changes) -> dict:
    return {"type": "add", "t": t, "id": cid, "constraint": {**hole().to_dict(), **changes}}


HEADERS = [
    ("robot 5", {"robot": 5}, r"header 'robot' must be a built-in robot name or a URDF path, got 5"),
    ("robot null", {"robot": None}, r"header 'robot' must be .*, got None"),
    ("robot 'abc'", {"robot": "abc"}, r"no URDF file at 'abc'"),
    ("robot ''", {"robot": ""}, r"header 'robot' must be"),
    ("rate_hz 'abc'", {"rate_hz": "abc"}, r"header 'rate_hz' must be a number, got 'abc'"),
    ("rate_hz null", {"rate_hz": None}, r"header 'rate_hz' must be a number, got None"),
    ("rate_hz [1000]", {"rate_hz": [1000]}, r"header 'rate_hz' must be a number, got \[1000\]"),
    ("rate_hz true", {"rate_hz": True}, r"header 'rate_hz' must be a number, got True"),
    ("rate_hz 10**400", {"rate_hz": 10**400}, r"header 'rate_hz' must be finite"),
    ("rate_hz 1e308", {"rate_hz": 1e308}, r"header 'rate_hz' must be <= 10000"),
    ("rate_hz 0", {"rate_hz": 0}, r"header 'rate_hz' must be > 0"),
    ("kp 'abc'", {"kp": "abc"}, r"header 'kp' must be a number"),
    ("kp -1", {"kp": -1}, r"header 'kp' must be > 0"),
    ("smoothing 1e300", {"target_time_constant_s": 1e300},
     r"header 'target_time_constant_s' must be <= 1"),
    ("q0 an object", {"q0": {"a": 1}}, r"header 'q0' must be a list of joint coordinates"),
    ("q0 'abc'", {"q0": "abc"}, r"header 'q0' must be a list"),
    ("q0 with a string", {"q0": [0.0, "a"]}, r"header 'q0' must be an array of 2 numbers"),
    ("q0 of the wrong size", {"q0": [0.0, 0.0, 0.0]}, r"header 'q0' has 3 values, the robot has nq = 8"),
    ("version true", {"version": True}, r"unsupported version True"),
    ("version '2'", {"version": "2"}, r"unsupported version '2'"),
    ("ee_frame a list", {"ee_frames": None, "ee_frame": ["tool0"]},
     r"header 'ee_frame' must be a name"),
    ("ee_frames a string", {"ee_frames": "tool0"}, r"header 'ee_frames' must be a list of frame names"),
    ("root_joint 5", {"root_joint": 5}, r"header 'root_joint' must be a name"),
    ("link_axis 'abc'", {"link_axis": "abc"}, r"header 'link_axis' must be an array of 3 numbers"),
    ("locked_joints 5", {"locked_joints": 5}, r"header 'locked_joints' must map joint names"),
    ("plant 'mujoco'", {"plant": "mujoco"}, r"header 'plant' must be an object, got 'mujoco'"),
    ("plant kind rigid", {"plant": {"kind": "rigid"}},
     r"header 'plant': plant must be one of kinematic, mujoco, ros2, got 'rigid'"),
    ("plant payload -1", {"plant": {"kind": "mujoco", "settings": {"payload_kg": -1}}},
     r"header 'plant': payload must be in \[0, 100\] kg, got -1"),
    ("plant unknown setting", {"plant": {"kind": "mujoco", "settings": {"mass": 1}}},
     r"header 'plant' 'settings' has unknown fields \['mass'\]"),
    ("plant stiffness nan", {"plant": {"kind": "mujoco", "wall_stiffness_n_per_m": "nan"}},
     r"header 'plant': wall_stiffness must be a number"),
]


def load_and_plan(path):
    return session_plan(load_session(path))


@pytest.mark.parametrize("changes, pattern", [pytest.param(changes, pattern, id=name)
                                              for name, changes, pattern in HEADERS])
def test_a_bad_session_header_names_the_file_line_and_field(changes, pattern, tmp_path):
    path = tmp_path / "session.jsonl"
    path.write_text(session_text(session_header(**changes), {"type": "end", "t": 0.1}))
    with pytest.raises(SessionError) as error:
        load_and_plan(path)
    assert_one_line(str(error.value), "^" + re.escape(f"{path}:1: ") + ".*" + pattern)


EVENTS = [
    ("gain 'abc'", [hole_added(gain="abc")], 2, r"bad hole: gain must be a number, got 'abc'"),
    ("gain -500", [hole_added(gain=-500)], 2, r"bad hole: gain must be >= 0"),
    ("gain null", [hole_added(gain=None)], 2, r"bad hole: gain must be a number, got None"),
    ("end at 1e12 s", [{"type": "end", "t": 1e12}], 2,
     r"'t' must be a time in \[0, 3600\] s, got 1000000000000.0$"),
    ("t 'abc'", [{"type": "end", "t": "abc"}], 2, r"'t' must be a time"),
    ("t true", [{"type": "end", "t": True}], 2, r"'t' must be a time .*got True"),
    ("nested JSON", [DEEP], 2, r"JSON nested too deeply$"),
    ("a 5000-digit integer", ['{"type": "end", "t": ' + "9" * 5000 + "}"], 2,
     r"not readable JSON"),
    ("duplicate id", [hole_added(0.0), hole_added(0.5)], 3,
     r"duplicate id 'hole-1': the constraint added at line 2 still holds it"),
    ("move of no constraint", [{"type": "move", "t": 0.1, "id": "x", "position": [0, 0, 0]}], 2,
     r"no constraint with id 'x' to move"),
    ("target position strings", [{"type": "target", "t": 0.1, "position": ["a", 0, 0],
                                  "quaternion_wxyz": [1, 0, 0, 0]}], 2,
     r"target 'position' must be an array of 3 numbers"),
    ("unknown event type", [{"type": 5, "t": 0}], 2, r"unknown event type 5"),
]


@pytest.mark.parametrize("events, line, pattern", [
    pytest.param(events, line, pattern, id=name) for name, events, line, pattern in EVENTS])
def test_a_bad_session_event_names_the_file_line_and_field(events, line, pattern, tmp_path):
    path = tmp_path / "session.jsonl"
    path.write_text(session_text(session_header(), *events))
    with pytest.raises(SessionError) as error:
        load_and_plan(path)
    assert_one_line(str(error.value), "^" + re.escape(f"{path}:{line}: ") + pattern)


def test_an_id_added_again_after_its_removal_is_no_duplicate(tmp_path):
    path = tmp_path / "session.jsonl"
    path.write_text(session_text(session_header(), hole_added(0.0),
                                 {"type": "remove", "t": 0.2, "id": "hole-1"}, hole_added(0.3),
                                 {"type": "end", "t": 0.4}))
    assert [e["type"] for e in load_session(path).events] == ["add", "remove", "add", "end"]


# ----------------------------------------------------------------------------- scene files


def scene(**changes) -> dict:
    data = {"format": "cjm-teleop-scene", "version": 1, "robot": {"source": ROBOT},
            "controllers": {"main": "cjm"}, "gain": 100.0, "damping": 0.0, "rate": 1000.0,
            "q": {"main": robot().q_home.tolist()},
            "target": {"position": [0.3, 0.0, 0.3], "wxyz": [1.0, 0.0, 0.0, 0.0]}}
    return {**data, **changes}


def test_the_scene_of_the_table_is_valid():
    assert parse_scene(scene(), robot().model.nq).damping == 0.0


SCENES = [
    ("ee_frame a list", {"robot": {"source": ROBOT, "ee_frame": ["tool0"]}},
     r"^scene robot.ee_frame must be a name, got \['tool0'\]$"),
    ("ee_frames a string", {"robot": {"source": ROBOT, "ee_frames": "tool0"}},
     r"^scene robot.ee_frames must be a list of names"),
    ("link_axis 'abc'", {"robot": {"source": ROBOT, "link_axis": "abc"}},
     r"^scene robot.link_axis must be an array of 3 numbers"),
    ("robot source 5", {"robot": {"source": 5}}, r"^scene 'robot' must be an object with a 'source'"),
    ("damping 1e300", {"damping": 1e300}, r"^scene damping must be <= 1, got 1e\+300$"),
    ("damping -1", {"damping": -1}, r"^scene damping must be >= 0"),
    ("rate 1e12", {"rate": 1e12}, r"^scene rate must be <= 10000"),
    ("rate 'abc'", {"rate": "abc"}, r"^scene rate must be a number"),
    ("gain 'abc'", {"gain": "abc"}, r"^scene gain must be a number"),
    ("version true", {"version": True}, r"^scene version True is not supported"),
    ("q.main strings", {"q": {"main": ["a"] * 8}}, r"^scene q.main must be an array of 8 numbers"),
]


@pytest.mark.parametrize("changes, pattern", [pytest.param(changes, pattern, id=name)
                                              for name, changes, pattern in SCENES])
def test_a_bad_scene_names_the_field(changes, pattern):
    with pytest.raises(ValueError) as error:
        parse_scene(scene(**changes), robot().model.nq)
    assert_one_line(str(error.value), pattern)


@pytest.mark.parametrize("text, pattern", [
    pytest.param(DEEP, r"JSON nested too deeply$", id="nested JSON"),
    pytest.param("{", r": not JSON \(Expecting property name enclosed in double quotes, column 2\)$",
                 id="not JSON"),
    pytest.param('{"rate": ' + "9" * 5000 + "}", r": not readable JSON", id="5000-digit integer"),
])
def test_a_bad_scene_file_is_one_line(text, pattern, tmp_path):
    path = tmp_path / "scene.json"
    path.write_text(text)
    with pytest.raises(ValueError) as error:
        read_scene_file(path)
    assert_one_line(str(error.value), pattern)


# ----------------------------------------------------------------------------- the CLI


def session_file(tmp, *events, **changes) -> str:
    path = tmp / "session.jsonl"
    path.write_text(session_text(session_header(**changes), *events))
    return str(path)


def out(tmp) -> list[str]:
    return ["--out", str(tmp / "out"), "--no-plots", "--quiet"]


def a_file(tmp) -> str:
    path = tmp / "file.txt"
    path.write_text("keep me\n")
    return str(path)


COMPARE = ["compare", "--scenario", "paper-hole"]
CLI = [
    ("compare --latency 1e9", lambda tmp: [*COMPARE, "--latency", "1000000000", *out(tmp)],
     r"argument --latency: must be in \[0, 10000\], got 1000000000"),
    ("compare --latency 5 s", lambda tmp: [*COMPARE, "--latency", "5000", *out(tmp)],
     r"^teleop compare: latency must be <= 1 s, got 5000 periods"),
    ("compare --rate 1e12", lambda tmp: [*COMPARE, "--rate", "1e12", *out(tmp)],
     r"argument --rate: must be in \(0, 10000\] Hz, got 1e\+12"),
    ("compare --rate nan", lambda tmp: [*COMPARE, "--rate", "nan", *out(tmp)],
     r"argument --rate: must be in"),
    ("compare --rate abc", lambda tmp: [*COMPARE, "--rate", "abc", *out(tmp)],
     r"argument --rate: must be a number, got 'abc'"),
    ("compare --duration 1e300", lambda tmp: [*COMPARE, "--duration", "1e300", *out(tmp)],
     r"argument --duration: must be in \(0, 3600\] s"),
    ("compare an hour at 10 kHz", lambda tmp: [*COMPARE, "--duration", "3600", "--rate", "10000",
                                               *out(tmp)],
     r"^teleop compare: duration 3600 s at 10000 Hz is 36000000 control periods"),
    ("compare --encoder-noise 1e6", lambda tmp: [*COMPARE, "--encoder-noise", "1e6", *out(tmp)],
     r"argument --encoder-noise: must be in \[0, 0.1\] rad"),
    ("compare --joint-time-constant 1e9",
     lambda tmp: [*COMPARE, "--joint-time-constant", "1e9", *out(tmp)],
     r"argument --joint-time-constant: must be in \[0, 1\] s"),
    ("compare --out /dev/null", lambda tmp: [*COMPARE, "--out", "/dev/null"],
     r"^teleop compare: output directory '/dev/null' exists and is not a directory$"),
    ("compare --out a file", lambda tmp: [*COMPARE, "--out", a_file(tmp)],
     r"^teleop compare: output directory '.*file.txt' exists and is not a directory$"),
    ("compare --scenario nope", lambda tmp: ["compare", "--scenario", "nope", *out(tmp)],
     r"^teleop compare: unknown scenario 'nope'"),
    ("compare --controllers nope", lambda tmp: [*COMPARE, "--controllers", "nope", *out(tmp)],
     r"^teleop compare: unknown controller 'nope'"),
    ("record --duration 1e12", lambda tmp: ["record", "--scenario", "paper-hole", "--duration",
                                            "1e12", str(tmp / "s.jsonl")],
     r"argument --duration: must be in \(0, 3600\] s"),
    ("record --rate 1e12", lambda tmp: ["record", "--scenario", "paper-hole", "--rate", "1e12",
                                        str(tmp / "s.jsonl")],
     r"argument --rate: must be in \(0, 10000\] Hz"),
    ("record onto a directory", lambda tmp: ["record", "--scenario", "paper-hole", "--duration",
                                             "0.01", str(tmp)],
     r"^teleop record: session file '.*' is a directory$"),
    ("bench --robots nope", lambda tmp: ["bench", "--robots", "nope", "--quick", "--no-scaling"],
     r"^teleop bench: unknown robot 'nope'"),
    ("bench --iterations 0", lambda tmp: ["bench", "--iterations", "0"],
     r"argument --iterations: must be in \[1, 1000000\], got 0"),
    ("bench --iterations 1e12", lambda tmp: ["bench", "--iterations", "1000000000000"],
     r"argument --iterations: must be in \[1, 1000000\]"),
    ("replay a missing file", lambda tmp: ["replay", str(tmp / "none.jsonl"), *out(tmp)],
     r"^teleop replay: no session file at"),
    ("replay rate_hz 1e308", lambda tmp: ["replay", session_file(tmp, rate_hz=1e308), *out(tmp)],
     r"^teleop replay: .*session.jsonl:1: header 'rate_hz' must be <= 10000"),
    ("replay robot 5", lambda tmp: ["replay", session_file(tmp, robot=5), *out(tmp)],
     r"^teleop replay: .*session.jsonl:1: header 'robot' must be"),
    ("replay end at 1e12 s", lambda tmp: ["replay", session_file(tmp, {"type": "end", "t": 1e12}),
                                          *out(tmp)],
     r"^teleop replay: .*session.jsonl:2: 't' must be a time in \[0, 3600\] s"),
    ("replay nested JSON", lambda tmp: ["replay", session_file(tmp, DEEP), *out(tmp)],
     r"^teleop replay: .*session.jsonl:2: JSON nested too deeply$"),
    ("replay duplicate ids", lambda tmp: ["replay", session_file(tmp, hole_added(0.0),
                                                                 hole_added(0.1)), *out(tmp)],
     r"^teleop replay: .*session.jsonl:3: duplicate id 'hole-1'"),
    ("replay --rate 1e12", lambda tmp: ["replay", session_file(tmp), "--rate", "1e12", *out(tmp)],
     r"argument --rate: must be in \(0, 10000\] Hz"),
    ("compare --plant rigid", lambda tmp: [*COMPARE, "--plant", "rigid", *out(tmp)],
     r"argument --plant: invalid choice: 'rigid'"),
    ("compare --payload -1", lambda tmp: [*COMPARE, "--plant", "mujoco", "--payload", "-1",
                                          *out(tmp)],
     r"argument --payload: must be in \[0, 100\] kg, got -1"),
    ("compare --payload nan", lambda tmp: [*COMPARE, "--plant", "mujoco", "--payload", "nan",
                                           *out(tmp)],
     r"argument --payload: must be in \[0, 100\] kg, got nan"),
    ("compare --payload on the kinematic plant",
     lambda tmp: [*COMPARE, "--payload", "0.5", "--coulomb-friction", "1", *out(tmp)],
     r"^teleop compare: --payload, --coulomb-friction need --plant mujoco"),
    ("compare --wall-stiffness abc", lambda tmp: [*COMPARE, "--wall-stiffness", "abc", *out(tmp)],
     r"argument --wall-stiffness: must be a number, got 'abc'"),
    ("compare --wall-stiffness inf", lambda tmp: [*COMPARE, "--wall-stiffness", "inf", *out(tmp)],
     r"argument --wall-stiffness: must be in \[0, 100\] N/mm, got inf"),
    ("compare --physics-rate 100", lambda tmp: [*COMPARE, "--plant", "mujoco", "--physics-rate",
                                                "100", *out(tmp)],
     r"argument --physics-rate: must be in \[2000, 100000\] Hz, got 100"),
    ("compare --servo-bandwidth 0", lambda tmp: [*COMPARE, "--plant", "mujoco",
                                                 "--servo-bandwidth", "0", *out(tmp)],
     r"argument --servo-bandwidth: must be in \(0, 200\] Hz, got 0"),
    ("compare --viscous-friction -1", lambda tmp: [*COMPARE, "--plant", "mujoco",
                                                   "--viscous-friction", "-1", *out(tmp)],
     r"argument --viscous-friction: must be in \[0, 10000\] N m s/rad, got -1"),
    ("record --payload on the kinematic plant",
     lambda tmp: ["record", "--scenario", "paper-hole", "--payload", "1", str(tmp / "s.jsonl")],
     r"^teleop record: --payload needs --plant mujoco"),
    ("bench --payload on the kinematic plant",
     lambda tmp: ["bench", "--payload", "1", "--quick", "--no-scaling"],
     r"^teleop bench: --payload needs --plant mujoco"),
    ("replay a bad plant", lambda tmp: ["replay", session_file(tmp, plant={"kind": "rigid"}),
                                        *out(tmp)],
     r"^teleop replay: .*session.jsonl:1: header 'plant': plant must be one of"),
    ("replay --friction on its kinematic plant",
     lambda tmp: ["replay", session_file(tmp), "--viscous-friction", "1", *out(tmp)],
     r"^teleop replay: --viscous-friction needs --plant mujoco"),
]


@pytest.mark.parametrize("argv, pattern", [pytest.param(argv, pattern, id=name)
                                           for name, argv, pattern in CLI])
def test_the_cli_prints_one_line_and_exits_2(argv, pattern, tmp_path, capsys):
    try:
        code = teleop_main(argv(tmp_path))
    except SystemExit as exit:  # argparse's errors
        code = exit.code
    captured = capsys.readouterr()
    assert code == 2, captured
    assert captured.out == ""
    assert_one_line(captured.err, pattern)
    assert not (tmp_path / "out").exists()  # refused before any output


@pytest.mark.parametrize("argv, pattern", [
    pytest.param(["compare", "--scenario", "paper-hole", "--latency", "1000000000"],
                 r"argument --latency: must be in", id="compare --latency 1e9"),
    pytest.param(["replay", "NESTED"], r"session.jsonl:2: JSON nested too deeply$",
                 id="replay nested JSON"),
])
def test_the_console_script_prints_one_line_and_no_traceback(argv, pattern, tmp_path):
    """Through the real process (the table above runs ``main`` in this one)."""
    argv = [session_file(tmp_path, DEEP) if arg == "NESTED" else arg for arg in argv]
    run = subprocess.run([sys.executable, "-m", "teleop.cli", *argv], capture_output=True,
                         text=True, timeout=120, cwd=tmp_path)
    assert run.returncode == 2, run.stderr
    assert_one_line(run.stderr, pattern)
