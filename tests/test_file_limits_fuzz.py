"""Fuzz of the files and command lines: every bad number, list, link or count a session, a
scene or a sweep spec carries, and every bad number given to any numeric option of any
command, is refused with one line naming the field or option (a session's with its file and
line), never another exception nor a run, and every input that could run without end is
bounded (docs/sessions.md, "Limits"; the one table: :mod:`teleop.limits`). 2,820 bad
inputs on 2026-11-29: 658 sessions, 453 scenes, 192 sweep specs, 1,517 command lines (the
command lines grow with the options; the last test prints the counts).

The table is generated: each field of each constraint kind, obstacle kind, collision
setting, session header and spec, crossed with the bad values of its type (wrong types,
null, NaN, infinities, an integer of 400 digits, values beyond the table's bounds). Each
row goes through the public entry point: a session is loaded and its plan started (the
constraint edits of time 0 applied, as a replay does), a scene applied to a running app
(``TeleopApp.scenes.apply``, without a browser), a spec loaded from its file.
"""

from __future__ import annotations

import inspect
import json
import re
import socket
import time
from functools import cache

import pinocchio as pin
import pytest

from constraints import Barrier, Hole, Plane, PointLock
from constraints.registry import constraint_type
from constraints.collision.obstacles import Box, Capsule, HalfSpace, Sphere
from teleop import load_robot
from teleop.cli.main import main as teleop_main
from teleop.experiments.sessions import load_session, session_plan
from teleop.experiments.sweep.ray_engine import CONNECT_TIMEOUT_S, check_address
from teleop.experiments.sweep.spec import load_spec
from teleop.limits import (MAX_CELLS_UNCONFIRMED, MAX_COLLISION_DISTANCE_M, MAX_CONSTRAINT_GAIN,
                           MAX_OBSTACLE_SIZE_M, MAX_OBSTACLES, MAX_POSE_GAIN, MAX_POSITION_M,
                           MAX_RESPONSE_TIME_S, MAX_SPEC_BYTES, MAX_SPEED_M_S,
                           MAX_TISSUE_DAMPING,
                           MAX_TISSUE_STIFFNESS)
from web.app import TeleopApp

ROBOT = "ur5_instrument"
#: the Python step: these tests are of the inputs, not of a build of the compiled one
CONTROLLER = "cjm:python"

#: Not a finite number: each numeric field refuses all of them.
NOT_NUMBERS = ["abc", None, True, [1.0], {"v": 1.0}, float("nan"), float("inf"),
               -float("inf"), 10**400]
#: Not a finite 3-vector.
NOT_VECTORS = ["abc", None, 5, [1.0, 2.0], [[1.0, 2.0, 3.0]], [True, 0, 0], ["a", 0, 0],
               [float("nan"), 0, 0], [10**400, 0, 0], {"x": 1.0}]
#: Points beyond the table's bound (m).
FAR = [[1e308, 0, 0], [0, -1e6, 0], [0, 0, 1.01 * MAX_POSITION_M]]
#: Velocities beyond the table's bound (m/s).
FAST = [[1e308, 0, 0], [0, 0, -1.01 * MAX_SPEED_M_S]]
#: Not a unit 3-vector.
NOT_UNIT = NOT_VECTORS + [[0, 0, 0], [0, 0, 2.0]]
#: Not a link of the robot.
NOT_LINKS = [5, None, "", ["tool0"], "abc", 10**400]
#: Not a list of link pairs (a non-list was a TypeError).
NOT_PAIRS = [5, 1.5, True, None, "abc", {"a": "b"}, [["a"]], [[1, 2]], [["abc", "def"]],
             [None], [["tool0"]], 10**400, [["tool0", "tool0", "x"]]]


@cache
def robot():
    return load_robot(ROBOT)


def constraint_dicts() -> dict[str, dict]:
    """A valid constraint of each kind, as a file carries it, on the robot at home."""
    r, q = robot(), robot().q_home
    return {"hole": Hole.on_link(r, q, 0.08).to_dict()
            | {"tissue_stiffness": 2000.0, "tissue_damping": 20.0},
            "plane": Plane.through_link_point(r, q, [0, 0, 1], distance=0.08).to_dict(),
            "barrier": Barrier.through_link_point(r, q, [0, 0, 1], distance=0.08).to_dict(),
            "point_lock": PointLock.on_link(r, q, distance=0.08).to_dict()}


#: Per field of a constraint: its bad values beyond the wrong types.
CONSTRAINT_FIELDS = {
    "gain": NOT_NUMBERS + [-1.0, 1.01 * MAX_CONSTRAINT_GAIN, 1e308],
    "tissue_stiffness": NOT_NUMBERS + [-1.0, 1e6, 1e10, 1e308],
    "tissue_damping": NOT_NUMBERS + [-1.0, 1.01 * MAX_TISSUE_DAMPING, 1e308],
    "center": NOT_VECTORS + FAR, "link_point": NOT_VECTORS + FAR,
    "plane_point": NOT_VECTORS + FAR, "target": NOT_VECTORS + FAR,
    "velocity": NOT_VECTORS + FAST, "link_axis": NOT_UNIT, "normal": NOT_UNIT,
    "link": NOT_LINKS,
}

#: A valid obstacle of each kind, far from the arm.
OBSTACLES = {"sphere": Sphere([1.5, 0, 0], 0.05).to_dict(),
             "box": Box([1.5, 0, 0], [0.1, 0.1, 0.1]).to_dict(),
             "capsule": Capsule([1.5, 0, 0], 0.05, 0.2).to_dict(),
             "halfspace": HalfSpace([0, 0, -1.0], [0, 0, 1]).to_dict()}
#: Per field of an obstacle: its bad values.
OBSTACLE_FIELDS = {
    "center": NOT_VECTORS + FAR, "velocity": NOT_VECTORS + FAST,
    "radius": NOT_NUMBERS + [0.0, -1.0, 1.01 * MAX_OBSTACLE_SIZE_M, 1e308],
    "length": NOT_NUMBERS + [-1.0, 1.01 * MAX_OBSTACLE_SIZE_M, 1e308],
    "size": NOT_VECTORS + [[1e308, 1, 1], [0, 1, 1], [1, 1.01 * MAX_OBSTACLE_SIZE_M, 1]],
    "rpy": NOT_VECTORS, "axis": NOT_UNIT, "normal": NOT_UNIT, "name": [5, "", " ", ["a"]],
}
#: Per collision setting: its bad values.
COLLISION_FIELDS = {
    "safety_distance": NOT_NUMBERS + [-1.0, 1.01 * MAX_COLLISION_DISTANCE_M, 1e308],
    "detection_distance": NOT_NUMBERS + [0.001, 1.01 * MAX_COLLISION_DISTANCE_M, 1e308],
    "approach_speed": NOT_NUMBERS + [0.0, -1.0, 1.01 * MAX_SPEED_M_S, 1e308],
    "self_collision": ["yes", 1, None, [True], 10**400],
    "disabled_pairs": NOT_PAIRS, "extra_pairs": NOT_PAIRS,
    "response_time": NOT_NUMBERS + [-1.0, 1.01 * MAX_RESPONSE_TIME_S, 1e308],
}
#: Not a list of obstacles, or too many of them.
BAD_OBSTACLE_LISTS = [5, "abc", {"kind": "sphere"}, None, [5], [{"kind": "nope"}],
                      [OBSTACLES["sphere"]] * (MAX_OBSTACLES + 1), [OBSTACLES["sphere"]] * 2000]


def constraint_cases():
    """(name, the constraint dict, the field its message names)."""
    for kind, valid in constraint_dicts().items():
        defaults = {name: field.default
                    for name, field in inspect.signature(constraint_type(kind)).parameters.items()}
        for name, values in CONSTRAINT_FIELDS.items():
            if name not in valid:
                continue
            for value in values:
                if value is None and defaults[name] is None:
                    continue  # null: the kind's default (a plane's gain)
                yield f"{kind}.{name}={short(value)}", valid | {name: value}, name


def obstacle_cases():
    """(name, the obstacle dict, the field its message names)."""
    for kind, valid in OBSTACLES.items():
        fields = set(valid) | {"velocity", "name"} | ({"rpy"} if kind == "box" else set()) \
            | ({"axis"} if kind == "capsule" else set())
        for name, values in OBSTACLE_FIELDS.items():
            if name not in fields:
                continue
            for value in values:
                yield f"{kind}.{name}={short(value)}", valid | {name: value}, name


def collision_cases():
    """(name, the collision settings' changes, the obstacles, the field its message names)."""
    for name, values in COLLISION_FIELDS.items():
        for value in values:
            yield f"collisions.{name}={short(value)}", {name: value}, [], name
    for value in BAD_OBSTACLE_LISTS:
        yield f"obstacles={short(value)}", {}, value, "obstacle"
    for name, obstacle, field in obstacle_cases():
        yield f"obstacle {name}", {}, [obstacle], field


def short(value) -> str:
    text = repr(value) if not isinstance(value, list) or len(value) < 5 else f"[{len(value)} items]"
    return text if len(text) < 40 else text[:37] + "..."


def assert_names(error: BaseException, field: str, prefix: str = "") -> None:
    """One line starting with ``prefix`` that names ``field`` (underscores or spaces)."""
    message = str(error)
    assert "\n" not in message.strip() and "Traceback" not in message, message
    assert message.startswith(prefix), (prefix, message)
    words = field.replace("_", "[_ ]")
    assert re.search(words, message, re.IGNORECASE), (field, message)


# ----------------------------------------------------------------------------- sessions


def session_header(**changes) -> dict:
    header = {"type": "header", "format": "cjm-teleop-session", "version": 4, "robot": ROBOT,
              "q0": robot().q_home.tolist(), "rate_hz": 1000, "kp": 20,
              "target_time_constant_s": 0.05}
    return header | changes


def collisions(changes: dict, obstacles: list) -> dict:
    return {"safety_distance": 0.005, "detection_distance": 0.05, "approach_speed": 0.5,
            "self_collision": False, "disabled_pairs": [], "extra_pairs": [],
            "obstacles": obstacles} | changes


def start_session(path) -> None:
    """What a replay does before its first step: load, plan, apply the edits of time 0."""
    plan = session_plan(load_session(path), robot())
    plan.update(0.0, plan.make_constraints(), plan.q0)


#: Header fields and their bad values (the constraints' and collisions' come from above).
HEADER_FIELDS = {
    "rate_hz": NOT_NUMBERS + [0, -1, 1e12, 1e308],
    "kp": NOT_NUMBERS + [0, -1, 1.01 * MAX_POSE_GAIN, 1e308],
    "target_time_constant_s": NOT_NUMBERS + [-1, 1e308],
}
PLANT_FIELDS = {
    "wall_stiffness_n_per_m": [v for v in NOT_NUMBERS if v is not None]  # null: each hole's
    + [-1.0, 1.01 * MAX_TISSUE_STIFFNESS, 1e10, 1e308],
    "payload_kg": NOT_NUMBERS + [-1.0, 101.0, 1e308],
    "physics_rate_hz": NOT_NUMBERS + [100.0, 1e6, 1e308],
    "servo_bandwidth_hz": NOT_NUMBERS + [0.0, 1e3, 1e308],
    "coulomb_friction_nm": NOT_NUMBERS + [-1.0, 1e5, 1e308],
    "viscous_friction_nms": NOT_NUMBERS + [-1.0, 1e5, 1e308],
    "armature_kg_m2": NOT_NUMBERS + [0.0, 1e4, 1e308],
}
#: Events and their bad fields.
TARGET = {"type": "target", "t": 0.01, "position": [0.3, 0.0, 0.3],
          "quaternion_wxyz": [1.0, 0.0, 0.0, 0.0]}
EVENT_FIELDS = {"position": NOT_VECTORS + FAR, "velocity": NOT_VECTORS + FAST}


def session_cases():
    """(name, header changes, events, the line at fault, the field its message names)."""
    for name, values in HEADER_FIELDS.items():
        for value in values:
            yield f"header {name}={short(value)}", {name: value}, [], 1, name
    for name, values in PLANT_FIELDS.items():
        for value in values:
            plant = ({"kind": "mujoco", name: value} if name == "wall_stiffness_n_per_m"
                     else {"kind": "mujoco", "settings": {name: value}})
            field = "wall_stiffness" if name == "wall_stiffness_n_per_m" else name.rsplit("_", 1)[0]
            if name == "armature_kg_m2":
                field = "armature"
            yield f"plant {name}={short(value)}", {"plant": plant}, [], 1, field
    for name, changes, obstacles, field in collision_cases():
        yield name, {"collisions": collisions(changes, obstacles)}, [], 1, field
    for name, constraint, field in constraint_cases():
        event = {"type": "add", "t": 0.0, "id": "c-1", "constraint": constraint}
        yield f"add {name}", {}, [event], 2, field
    for name, values in EVENT_FIELDS.items():
        for value in values:
            move = {"type": "move", "t": 0.0, "id": "c-1", "position": [0.3, 0, 0.3], name: value}
            add = {"type": "add", "t": 0.0, "id": "c-1", "constraint": constraint_dicts()["hole"]}
            yield f"move {name}={short(value)}", {}, [add, move], 3, name
        if name == "position":
            for value in values:
                yield f"target position={short(value)}", {}, [TARGET | {name: value}], 2, name


SESSION_CASES = list(session_cases())


@pytest.mark.parametrize("header, events, line, field", [
    pytest.param(header, events, line, field, id=name)
    for name, header, events, line, field in SESSION_CASES])
def test_a_bad_session_number_is_one_line_at_its_file_and_line(header, events, line, field,
                                                               tmp_path):
    path = tmp_path / "session.jsonl"
    lines = [session_header(**header), *events, {"type": "end", "t": 0.1}]
    path.write_text("\n".join(json.dumps(item) for item in lines) + "\n")
    with pytest.raises(ValueError) as error:
        start_session(path)
    assert_names(error.value, field, f"{path}:{line}: ")


# ----------------------------------------------------------------------------- scenes


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    return TeleopApp(robot(), controller=CONTROLLER, record_dir=tmp_path_factory.mktemp("records"))


def scene(constraints=(), collision_changes=None, obstacles=()) -> dict:
    r = robot()
    pose = r.model.createData()
    pin.framesForwardKinematics(r.model, pose, r.q_home)
    ee = pose.oMf[r.model.getFrameId(r.ee_frame)]
    quaternion = pin.Quaternion(ee.rotation)
    settings = collisions(collision_changes or {}, []) | {"on": True}
    settings.pop("obstacles")
    return {"format": "cjm-teleop-scene", "version": 2, "robot": {"source": ROBOT},
            "controllers": {"main": CONTROLLER}, "gain": 100.0, "damping": 0.0, "rate": 1000.0,
            "q": {"main": r.q_home.tolist()},
            "target": {"position": ee.translation.tolist(),
                       "wxyz": [quaternion.w, quaternion.x, quaternion.y, quaternion.z]},
            "constraints": [{"id": f"c-{i + 1}", "constraint": c}
                            for i, c in enumerate(constraints)],
            "collisions": settings,
            "obstacles": obstacles if not isinstance(obstacles, (list, tuple)) else
            [{"id": f"o-{i + 1}", "obstacle": o} for i, o in enumerate(obstacles)]}


def test_the_valid_scene_and_session_of_the_tables_are_taken(app, tmp_path):
    app.scenes.apply(scene(list(constraint_dicts().values())[:1], {"self_collision": True},
                          list(OBSTACLES.values())))
    assert len(app.collisions.obstacles) == len(OBSTACLES)
    path = tmp_path / "session.jsonl"
    events = [session_header(collisions=collisions({}, list(OBSTACLES.values())),
                             plant={"kind": "mujoco", "wall_stiffness_n_per_m": 2000.0}),
              {"type": "add", "t": 0.0, "id": "c-1", "constraint": constraint_dicts()["hole"]},
              TARGET, {"type": "end", "t": 0.1}]
    path.write_text("\n".join(json.dumps(item) for item in events) + "\n")
    start_session(path)


def scene_cases():
    """(name, the scene, the field its message names)."""
    for name, constraint, field in constraint_cases():
        if field == "gain":
            continue  # a scene's constraints take the scene's gain (test_bad_inputs.py)
        yield f"constraint {name}", scene([constraint]), field
    for name, changes, obstacles, field in collision_cases():
        yield name, scene(collision_changes=changes, obstacles=obstacles), field


SCENE_CASES = list(scene_cases())


@pytest.mark.parametrize("data, field", [pytest.param(data, field, id=name)
                                         for name, data, field in SCENE_CASES])
def test_a_bad_scene_number_is_one_line_naming_the_field(app, data, field):
    with pytest.raises(ValueError) as error:
        app.scenes.apply(data)
    assert_names(error.value, field)


# ----------------------------------------------------------------------------- sweep specs

SPEC = {"scenarios": ["paper-hole"], "controllers": [CONTROLLER]}
#: Not a number or a list of distinct numbers (a list is the grid's values; null is the
#: default of an optional field, added to the others below).
SPEC_NOT_NUMBERS = ["abc", True, [[1.0]], ["abc"], [1.0, 1.0], {"v": 1.0}, float("nan"),
                    float("inf"), -float("inf"), 10**400]
SPEC_FIELDS = {
    "duration": SPEC_NOT_NUMBERS + [0, -1, 1e308],
    "rate": SPEC_NOT_NUMBERS + [None, 0, 1e12, 1e308],
    "payload": SPEC_NOT_NUMBERS + [None, -1, 1e308],
    "kp": SPEC_NOT_NUMBERS + [None, 0, 1.01 * MAX_POSE_GAIN, 1e308],
    "constraint_gain": SPEC_NOT_NUMBERS + [-1, 1.01 * MAX_CONSTRAINT_GAIN, 1e308],
    "seeds": ["abc", None, True, -1, 0, 10**400, [1.5], [True], [-1], [2**64]],
    "time_limit": SPEC_NOT_NUMBERS + [None, 0, 1e308],
    "plants": [5, None, "rigid", [1], [[1]]], "scenarios": [5, None, [], ["nope"], [[1]]],
    "controllers": [5, None, [], ["nope"], [[1]]],
}
SPEC_GROUPS = {
    "imperfections": {"encoder_noise": SPEC_NOT_NUMBERS + [None, -1, 1e6],
                      "latency": ["abc", None, True, 1.5, -1, 10**9, 10**400],
                      "joint_time_constant": SPEC_NOT_NUMBERS + [None, -1, 1e300],
                      "calibration_error_mm": SPEC_NOT_NUMBERS + [None, -1, 1e6],
                      "calibration_error_mrad": SPEC_NOT_NUMBERS + [None, -1, 1e6]},
    "variations": {"trocar_shift": SPEC_NOT_NUMBERS + [None, -1, 1e6],
                   "path_amplitude": SPEC_NOT_NUMBERS + [None, -1, 1e6]},
}


def spec_cases():
    """(name, the spec document, the field its message names)."""
    for name, values in SPEC_FIELDS.items():
        for value in values:
            yield f"{name}={short(value)}", SPEC | {name: value}, name
    for group, fields in SPEC_GROUPS.items():
        yield f"{group}=5", SPEC | {group: 5}, group
        for name, values in fields.items():
            for value in values:
                yield f"{group}.{name}={short(value)}", SPEC | {group: {name: value}}, name


SPEC_CASES = list(spec_cases())


@pytest.mark.parametrize("document, field", [pytest.param(document, field, id=name)
                                             for name, document, field in SPEC_CASES])
def test_a_bad_spec_number_is_one_line_naming_the_field(document, field, tmp_path):
    path = tmp_path / "spec.json"
    path.write_text(json.dumps(document))
    with pytest.raises(ValueError) as error:
        load_spec(path)
    assert_names(error.value, field, f"{path}: ")


# ----------------------------------------------------------------------------- command lines

#: Not a number the command line could take, for any option that takes numbers (``-inf``
#: and the like reach argparse as options: refused too, as missing values).
CLI_NOT_NUMBERS = ["abc", "", "nan", "inf", "-inf", "1e400", "-1e400", "1e308", "-1e308",
                   "0x10", "nan,nan", "1e308,1e308", "1,abc"]
#: What each command needs besides the option (a run that slipped through would be short:
#: a hundredth of a second of paper-hole, or a sweep of one such cell).
CLI_REQUIRED = {"compare": ["--scenario", "paper-hole", "--duration", "0.01"],
                "record": ["--scenario", "paper-hole", "--duration", "0.01", "session.jsonl"],
                "replay": ["missing.jsonl"], "bench": ["--quick"], "sim": [],
                "sweep": ["--scenarios", "paper-hole", "--controllers", CONTROLLER,
                          "--duration", "0.01"],
                "web": []}


def cli_options() -> list[tuple[str, str, int]]:
    """(command, option, values it takes) for every option of every command that takes
    numbers: its type is neither free text nor names, and it has no choices."""
    import argparse

    from teleop.cli.arguments import csv_list
    from teleop.cli.main import build_parser
    from teleop.options import Names, Text

    commands = next(action for action in build_parser()._actions
                    if isinstance(action, argparse._SubParsersAction)).choices
    return [(command, action.option_strings[0],
             action.nargs if isinstance(action.nargs, int) else 1)
            for command in CLI_REQUIRED for action in commands[command]._actions
            if action.option_strings and action.nargs != 0 and not action.choices
            and action.type not in (None, str, csv_list)
            and not isinstance(getattr(action.type, "__self__", None), (Text, Names))]


#: a robot's link axis is a direction of any length: 1e308 1e308 1e308 is (1, 1, 1) (it
#: overflowed to a zero axis, served: tests/test_robots.py)
CLI_VALID = {("--link-axis", "1e308")}
CLI_CASES = [(command, option, [value] * count) for command, option, count in cli_options()
             for value in CLI_NOT_NUMBERS if (option, value) not in CLI_VALID]


@pytest.mark.parametrize("command, option, values", [
    pytest.param(command, option, values, id=f"{command} {option}={values[0]!r}")
    for command, option, values in CLI_CASES])
def test_a_bad_command_line_number_is_one_line_naming_the_option(command, option, values,
                                                                  tmp_path, monkeypatch, capsys):
    """Refused while parsing (the option's type), or by the command before it runs anything
    (the value checked with the file's: ``teleop COMMAND: FIELD ...``); never a run."""
    import web.ui

    def never(*args, **kwargs):
        raise AssertionError("the page was served")

    monkeypatch.setattr(web.ui, "run_server", never)
    monkeypatch.chdir(tmp_path)
    fixed = CLI_REQUIRED[command]
    if option in fixed:  # the fuzzed option replaces its fixed value
        at = fixed.index(option)
        fixed = fixed[:at] + fixed[at + 2:]
    extra = ["--out", str(tmp_path / "out")] if command in ("compare", "sweep") else []
    code, err = cli([command, *fixed, *extra, option, *values], capsys)
    assert code == 2, (code, err)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    field = option.lstrip("-").replace("-", "_")
    assert option in err or re.search(field.replace("_", "[_ ]"), err, re.IGNORECASE), err


def test_the_tables_hold_over_two_thousand_bad_inputs():
    counts = {"session": len(SESSION_CASES), "scene": len(SCENE_CASES),
              "sweep spec": len(SPEC_CASES), "command line": len(CLI_CASES)}
    print(f"\n[bad inputs] {sum(counts.values())}: {counts}")
    assert sum(counts.values()) >= 2000


# ----------------------------------------------------------------------------- no end


@pytest.mark.parametrize("name, text, pattern", [
    ("spec.toml", "a = " + "[" * 100_000 + "]" * 100_000, r"spec.toml: TOML nested too deeply$"),
    ("spec.json", "[" * 100_000 + "]" * 100_000, r"spec.json: JSON nested too deeply$"),
    ("spec.json", " " * (MAX_SPEC_BYTES + 1), rf"a spec is at most {MAX_SPEC_BYTES} bytes"),
])
def test_a_spec_file_nested_or_long_without_end_is_one_line(name, text, pattern, tmp_path):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ValueError) as error:
        load_spec(path)
    assert "\n" not in str(error.value) and str(error.value).startswith(str(path))
    assert re.search(pattern, str(error.value)), str(error.value)


def cli(argv: list[str], capsys) -> tuple[int, str]:
    try:
        code = teleop_main(argv)
    except SystemExit as exit:  # argparse's errors
        code = exit.code
    captured = capsys.readouterr()
    assert captured.out == ""
    return code, captured.err


def test_sweep_reads_dev_zero_only_up_to_the_spec_limit(tmp_path, capsys):
    started = time.monotonic()
    code, err = cli(["sweep", "--spec", "/dev/zero", "--out", str(tmp_path / "out")], capsys)
    assert code == 2
    assert err == f"teleop sweep: /dev/zero: a spec is at most {MAX_SPEC_BYTES} bytes, this " \
                  "file is longer\n"
    assert time.monotonic() - started < 10.0
    assert not (tmp_path / "out").exists()


def test_a_grid_above_the_documented_size_needs_yes(tmp_path, capsys):
    argv = ["sweep", "--scenarios", "paper-hole", "--controllers", CONTROLLER, "--seeds",
            str(MAX_CELLS_UNCONFIRMED + 1), "--out", str(tmp_path / "out")]
    code, err = cli(argv, capsys)
    assert code == 2
    assert err == (f"teleop sweep: the grid has {MAX_CELLS_UNCONFIRMED + 1} cells, more than "
                   f"{MAX_CELLS_UNCONFIRMED}: give --yes to run them all\n")
    assert not (tmp_path / "out").exists()


def test_bench_refuses_an_unwritable_json_before_benchmarking(tmp_path, capsys):
    started = time.monotonic()
    code, err = cli(["bench", "--json", "/proc/x"], capsys)  # the full bench: minutes
    assert code == 2
    assert err == "teleop bench: cannot write --json '/proc/x': No such file or directory\n"
    assert time.monotonic() - started < 5.0
    code, err = cli(["bench", "--json", str(tmp_path)], capsys)
    assert (code, err) == (2, f"teleop bench: --json {str(tmp_path)!r} is a directory\n")
    assert list(tmp_path.iterdir()) == []


def test_a_ray_address_that_accepts_tcp_but_is_not_ray_fails_within_the_timeout():
    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        address = f"127.0.0.1:{server.getsockname()[1]}"
        started = time.monotonic()
        with pytest.raises(ValueError) as error:
            check_address(address)
        elapsed = time.monotonic() - started
    assert str(error.value) == (f"the Ray cluster at {address} did not answer within "
                                f"{CONNECT_TIMEOUT_S:g} s: is it a Ray head's address?")
    assert CONNECT_TIMEOUT_S <= elapsed < CONNECT_TIMEOUT_S + 1.0
