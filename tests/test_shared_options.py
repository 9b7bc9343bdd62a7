"""The options several front ends share are declared once (teleop/options.py and
teleop/plants/options.py, issue 34 item 6): ``teleop compare``, ``replay``, ``record``,
``bench``, ``sim``, ``teleop web``, ``teleop sweep``'s command line and its spec, and a
session's header refuse the same bad value with the same words, take the same good ones,
and only the commands a declaration names take its option."""

from __future__ import annotations

import argparse
import json
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from teleop.cli.main import build_parser, main
from teleop.experiments.sweep import build_spec
from teleop.options import COMMANDS, SHARED_OPTIONS, SWEEP, NumberRange, SharedOption
from teleop.plants import PlantChoice
from teleop.plants.options import PLANT_OPTIONS, PLANT_OPTIONS_BY_NAME
from teleop.plants.settings import SETTINGS_KEYS
from web import cli as web_cli

#: every declared option of a run and of the plants, by name
DECLARED: dict[str, SharedOption] = {**SHARED_OPTIONS,
                                     **{option.name: option.option for option in PLANT_OPTIONS}}

#: a value just outside each option's range, as text, and the words written by hand (the
#: choice: argparse's own words on a command line, the validator's in a file)
BAD = {
    "rate": ("0", "must be in (0, 10000] Hz, got 0"),
    "duration": ("-1", "must be in (0, 3600] s, got -1"),
    "payload": ("-1", "must be in [0, 100] kg, got -1"),
    "wall_stiffness": ("101", "must be in [0, 100] N/mm, got 101"),
    "kp": ("0", "must be in (0, 10000] 1/s, got 0"),
    "constraint_gain": ("20001", "must be in [0, 20000] 1/s, got 20001"),
    "jerk_limit": ("0", "must be in (0, 1e+08] rad/s^3, got 0"),
    "encoder_noise": ("0.2", "must be in [0, 0.1] rad, got 0.2"),
    "latency": ("10001", "must be in [0, 10000], got 10001"),
    "joint_time_constant": ("2", "must be in [0, 1] s, got 2"),
    "trocar_shift": ("2", "must be in [0, 1] m, got 2"),
    "path_amplitude": ("-0.5", "must be in [0, 1] m, got -0.5"),
    "seed": ("-1", "must be in [0, 9223372036854775807], got -1"),
    "calibration_error_mm": ("51", "must be in [0, 50] mm, got 51"),
    "calibration_error_mrad": ("201", "must be in [0, 200] mrad, got 201"),
    "coulomb_friction": ("-1", "must be in [0, 10000] N m, got -1"),
    "viscous_friction": ("10001", "must be in [0, 10000] N m s/rad, got 10001"),
    "physics_rate": ("1999", "must be in [2000, 100000] Hz, got 1999"),
    "servo_bandwidth": ("0", "must be in (0, 200] Hz, got 0"),
    "interface_limits": ("hard", "invalid choice: 'hard'"),
    "interface_jerk_limit": ("1e9", "must be in (0, 1e+08] rad/s^3, got 1e+09"),
    "joint_states": ("", "must be a non-empty text, got ''"),
    "command_topic": (" /a", "must be a non-empty text, got ' /a'"),
    "command_joints": (",", "must be one or more comma-separated names, got ','"),
    "crtk": ("", "must be a non-empty text, got ''"),
    "ros_domain": ("233", "must be in [0, 232], got 233"),
    "realtime_priority": ("100", "must be in [0, 99], got 100"),
    "response_time": ("61", "must be in [0, 60] s, got 61"),
}

#: a bad value in a file, and its words, where a file's differ from the command line's
BAD_IN_A_FILE: dict[str, tuple[Any, str]] = {
    "interface_limits": ("hard", "must be one of off, count, strict, got 'hard'"),
    "command_joints": ([], "must be a list of one or more names, got []"),
}

#: a good value of each option, as text, and the value every front end reads from it
GOOD: dict[str, tuple[str, Any]] = {
    "rate": ("500", 500.0), "duration": ("2.5", 2.5), "payload": ("0.5", 0.5),
    "wall_stiffness": ("2", 2.0), "kp": ("30", 30.0), "constraint_gain": ("5", 5.0),
    "jerk_limit": ("5000", 5000.0), "encoder_noise": ("1e-4", 1e-4), "latency": ("3", 3),
    "joint_time_constant": ("0.01", 0.01), "trocar_shift": ("0.02", 0.02),
    "path_amplitude": ("0.01", 0.01), "seed": ("7", 7), "calibration_error_mm": ("1", 1.0),
    "calibration_error_mrad": ("2", 2.0), "coulomb_friction": ("0.1", 0.1),
    "viscous_friction": ("0.2", 0.2), "physics_rate": ("4000", 4000.0),
    "servo_bandwidth": ("30", 30.0), "interface_limits": ("count", "count"),
    "interface_jerk_limit": ("5000", 5000.0), "joint_states": ("/js", "/js"),
    "command_topic": ("/c", "/c"), "command_joints": ("a, b", ("a", "b")),
    "crtk": ("/PSM1", "/PSM1"), "ros_domain": ("7", 7), "realtime_priority": ("0", 0),
    "response_time": ("0.02", 0.02),
}

#: the options another one must come with
COMPANIONS = {"interface_jerk_limit": {"interface_limits": "count"}}

#: ``teleop sim``'s own options of a declared option's name: the rate it serves the robot
#: at (from 1 Hz) and the wall-clock seconds it serves (default: until Ctrl-C)
HOMONYMS = {("sim", "rate"), ("sim", "duration")}

#: what each command needs besides the option (its required arguments)
REQUIRED = {
    "compare": ["compare", "--scenario", "paper-hole"],
    "replay": ["replay", "session.jsonl"],
    "record": ["record", "--scenario", "paper-hole", "session.jsonl"],
    "bench": ["bench"],
    "sim": ["sim", "--ros2"],
    "sweep": ["sweep", "--out", "sweep", "--scenarios", "paper-hole", "--controllers", "cjm"],
}


def test_every_declared_option_is_listed_here():
    assert set(DECLARED) == set(BAD) == set(GOOD)
    assert all(option.commands <= set(COMMANDS) for option in DECLARED.values())


def argparse_refusal(run, argv: list[str], capsys) -> str:
    """The one line a command prints when it refuses ``argv`` (exit code 2)."""
    try:
        code = run(argv)
    except SystemExit as stop:  # argparse's own refusal
        code = stop.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    return err


def command_line(command: str, given_option: list[str], tmp_path) -> tuple[Any, list[str]]:
    """How ``command`` is run with ``given_option``: (its main, its arguments)."""
    if command == "web":
        return web_cli.main, given_option
    argv = [str(tmp_path / arg) if arg.endswith(".jsonl") or arg == "sweep" and i > 0 else arg
            for i, arg in enumerate(REQUIRED[command])]
    return main, [*argv, *given_option]


def spec_refusal(name: str, text: str) -> str:
    """What a sweep's spec says to ``text`` (a JSON value) for field ``name``."""
    with pytest.raises(ValueError) as spec:
        build_spec({"scenarios": "paper-hole", "controllers": "cjm", name: json.loads(text)})
    return str(spec.value)


def refusal(command: str, name: str, text: str, capsys, tmp_path) -> str:
    """What ``command`` says when given ``text`` for option ``name``."""
    run, argv = command_line(command, [f"{DECLARED[name].option}={text}"], tmp_path)
    message = argparse_refusal(run, argv, capsys)
    if command == SWEEP:  # the command line's numbers are checked by the spec's validator
        assert not (tmp_path / "sweep").exists()
        assert spec_refusal(name, text) in message, message
    return message


@pytest.mark.parametrize("name", sorted(DECLARED))
def test_each_command_refuses_a_bad_value_with_the_same_words(name, capsys, tmp_path):
    text, words = BAD[name]
    option = DECLARED[name]
    for command in sorted(option.commands):
        message = refusal(command, name, text, capsys, tmp_path)
        assert words in message, (command, message)
        # the option by its name: argparse's "argument --rate: ...", the spec's "rate ..."
        assert (f"argument {option.option}: {words}" in message
                or f"{name} {words}" in message), (command, message)
    value, words = BAD_IN_A_FILE.get(name, (text, words))
    if isinstance(option.range, NumberRange):
        value = json.loads(text)
    with pytest.raises(ValueError) as checked:  # the validator of a file's value
        option.check(value)
    assert str(checked.value) == f"{name} {words}"


def parsed(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    return parser.parse_args(argv)


def parser_of(command: str) -> argparse.ArgumentParser:
    """``command``'s own parser (the subcommand's, or ``teleop web``'s)."""
    if command == "web":
        return web_cli.build_parser()
    commands = next(action for action in build_parser(registered=False)._actions
                    if isinstance(action, argparse._SubParsersAction))
    return commands.choices[command]


@pytest.mark.parametrize("name", sorted(DECLARED))
def test_each_command_takes_a_good_value_as_the_file_validator_reads_it(name, tmp_path):
    """The value a command line parses is the value the spec, session and keyword
    validator makes of the same input; the commands the declaration leaves out do not
    know the option at all."""
    text, value = GOOD[name]
    option = DECLARED[name]
    file_value = list(value) if isinstance(value, tuple) else value
    assert option.check(file_value) == value
    for command in COMMANDS:
        parser = parser_of(command)
        known = option.option in parser._option_string_actions
        if (command, name) in HOMONYMS:
            continue
        assert known == (command in option.commands), (command, option.option)
        if not known or command == SWEEP:
            continue
        argv = [*REQUIRED.get(command, [])[1:], f"{option.option}={text}"]
        assert getattr(parsed(parser, argv), name) == value, command
    if SWEEP in option.commands:
        plants = {"plants": "mujoco"} if name in PLANT_OPTIONS_BY_NAME else {}
        spec = build_spec({"scenarios": "paper-hole", "controllers": "cjm", **plants,
                           name: file_value})
        assert spec.grid[name] == [value]


@pytest.mark.parametrize("name", sorted(PLANT_OPTIONS_BY_NAME))
def test_a_plant_option_on_a_plant_that_does_not_take_it_is_refused_naming_both(name, capsys,
                                                                                tmp_path):
    plant_option = PLANT_OPTIONS_BY_NAME[name]
    text, value = GOOD[name]
    plants = " or ".join(plant_option.plants)
    for kind in ("kinematic", "mujoco", "ros2"):
        if kind in plant_option.plants:
            chosen = PlantChoice.with_options({name: value, **COMPANIONS.get(name, {})}, kind)
            assert chosen.kind == kind
            continue
        with pytest.raises(ValueError) as refused:
            PlantChoice.with_options({name: value}, kind)
        assert str(refused.value) == f"{plant_option.option.option} needs --plant {plants}"
        run, argv = command_line("compare", ["--plant", kind, f"{plant_option.option.option}="
                                             f"{text}"], tmp_path)
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err == f"teleop compare: {refused.value}\n", err


@pytest.mark.parametrize("name", sorted(option.name for option in PLANT_OPTIONS
                                        if option.holder == "physics"))
def test_a_sessions_physics_settings_are_refused_with_the_options_words(name):
    """A session header's plant settings go through the same validator."""
    text, words = BAD[name]
    if name in BAD_IN_A_FILE:
        value, words = BAD_IN_A_FILE[name]
        text = json.dumps(value)
    key = next(key for key, field in SETTINGS_KEYS.items() if field == name)
    with pytest.raises(ValueError) as refused:
        PlantChoice.from_dict({"kind": "mujoco", "settings": {key: json.loads(text)}},
                              "header 'plant'")
    assert str(refused.value) == f"header 'plant': {name} {words}"


@pytest.mark.parametrize("text, words", [
    ("fast", "must be a number, got 'fast'"),
    ("nan", "must be in (0, 10000] Hz, got nan"),
    ("inf", "must be in (0, 10000] Hz, got inf"),
])
def test_a_rate_that_is_not_a_finite_number_is_refused_alike(text, words, capsys):
    for run, argv in ((main, ["compare", "--scenario", "paper-hole", "--rate", text]),
                      (web_cli.main, ["--rate", text])):
        assert f"argument --rate: {words}" in argparse_refusal(run, argv, capsys)


@pytest.mark.parametrize("value, words", [
    ("1000", "rate must be a number, got '1000'"),
    (True, "rate must be a number, got True"),
    (float("nan"), "rate must be in (0, 10000] Hz, got nan"),
    (10**400, "rate must be in (0, 10000] Hz, got 1" + "0" * 400),
])
def test_a_spec_value_of_the_wrong_type_is_refused_naming_it(value, words):
    with pytest.raises(ValueError) as refused:
        build_spec({"scenarios": "paper-hole", "controllers": "cjm", "rate": value})
    assert words in str(refused.value)


def test_an_integer_option_refuses_a_fraction_in_a_spec_and_on_a_command_line(capsys):
    with pytest.raises(ValueError, match=r"latency must be an integer, got 1\.5"):
        build_spec({"scenarios": "paper-hole", "controllers": "cjm", "latency": 1.5})
    assert "argument --latency: must be an integer, got '1.5'" in argparse_refusal(
        main, ["compare", "--scenario", "paper-hole", "--latency", "1.5"], capsys)


@given(minimum=st.floats(-1e6, 1e6), width=st.floats(0.0, 1e6),
       value=st.floats(allow_nan=True, allow_infinity=True), inclusive=st.booleans())
def test_parsing_text_and_checking_a_value_agree(minimum, width, value, inclusive):
    """The argparse type and the spec's check take the same numbers and refuse the others
    with the same words (a float's text round-trips through ``repr``)."""
    bounds = NumberRange(float, minimum, minimum + width, inclusive_minimum=inclusive, unit="m")
    problem = bounds.problem(value)
    inside = (minimum <= value if inclusive else minimum < value) and value <= minimum + width
    assert (problem is None) == inside
    if problem is None:
        assert bounds.parse(repr(value)) == value == bounds.check(value, "x")
    else:
        with pytest.raises(ValueError) as checked:
            bounds.check(value, "x")
        assert str(checked.value) == f"x {problem}"
        with pytest.raises(Exception) as parsed:
            bounds.parse(repr(value))
        assert str(parsed.value) == problem
