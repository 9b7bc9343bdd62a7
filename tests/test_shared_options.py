"""The options several front ends share are defined once (teleop/options.py, issue 34 item 6):
``teleop compare``, ``replay``, ``record``, ``teleop web``, ``teleop sweep``'s command line
and its spec refuse the same bad value with the same words, and take the same good ones."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from teleop.cli.main import main
from teleop.experiments.sweep import build_spec
from teleop.options import SHARED_OPTIONS, NumberRange
from web import cli as web_cli

#: each shared option and the front ends that take it (the sweep: its command line and spec)
FRONT_ENDS = {
    "rate": ("compare", "replay", "record", "web", "sweep"),
    "duration": ("compare", "replay", "record", "sweep"),
    "payload": ("compare", "replay", "record", "web", "sweep"),
    "wall_stiffness": ("compare", "replay", "record", "web"),
    "kp": ("compare", "replay", "sweep"),
    "constraint_gain": ("compare", "replay", "sweep"),
    "jerk_limit": ("compare", "replay"),
    "encoder_noise": ("compare", "replay", "sweep"),
    "latency": ("compare", "replay", "sweep"),
    "joint_time_constant": ("compare", "replay", "sweep"),
    "trocar_shift": ("compare", "replay", "sweep"),
    "path_amplitude": ("compare", "replay", "sweep"),
    "seed": ("compare", "replay"),  # a sweep takes seeds: a count or a list
}

#: a value just outside each option's range, as text, and the words written by hand
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
}


def test_every_shared_option_is_listed_here():
    assert set(FRONT_ENDS) == set(BAD) <= set(SHARED_OPTIONS)


def argparse_refusal(run, argv: list[str], capsys) -> str:
    """The one line a command prints when it refuses ``argv`` (exit code 2)."""
    try:
        code = run(argv)
    except SystemExit as stop:  # argparse's own refusal
        code = stop.code
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    return err


def refusal(front_end: str, name: str, text: str, capsys, tmp_path) -> str:
    """What ``front_end`` says when given ``text`` for option ``name``."""
    option = SHARED_OPTIONS[name].option
    given_option = [f"{option}={text}"]
    if front_end == "compare":
        return argparse_refusal(main, ["compare", "--scenario", "paper-hole", *given_option],
                                capsys)
    if front_end == "replay":
        return argparse_refusal(main, ["replay", str(tmp_path / "none.jsonl"), *given_option],
                                capsys)
    if front_end == "record":
        return argparse_refusal(main, ["record", "--scenario", "paper-hole",
                                       str(tmp_path / "s.jsonl"), *given_option], capsys)
    if front_end == "web":
        return argparse_refusal(web_cli.main, given_option, capsys)
    assert front_end == "sweep"
    command_line = argparse_refusal(main, ["sweep", "--out", str(tmp_path / "sweep"),
                                           "--scenarios", "paper-hole", "--controllers", "cjm",
                                           *given_option], capsys)
    assert not (tmp_path / "sweep").exists()
    with pytest.raises(ValueError) as spec:
        build_spec({"scenarios": "paper-hole", "controllers": "cjm",
                    name: json.loads(text)})
    assert str(spec.value) in command_line, (spec.value, command_line)
    return str(spec.value)


@pytest.mark.parametrize("name", sorted(FRONT_ENDS))
def test_each_front_end_refuses_a_bad_value_with_the_same_words(name, capsys, tmp_path):
    text, words = BAD[name]
    for front_end in FRONT_ENDS[name]:
        message = refusal(front_end, name, text, capsys, tmp_path)
        assert words in message, (front_end, message)
        # the option by its name: argparse's "argument --rate: ...", the spec's "rate ..."
        assert (f"argument {SHARED_OPTIONS[name].option}: {words}" in message
                or f"{name} {words}" in message), (front_end, message)


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
