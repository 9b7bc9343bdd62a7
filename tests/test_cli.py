"""The command lines (``teleop``, ``teleop web``, ``python -m web``), the commands registered
from the layers above, and the controller registry."""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import textwrap
from importlib import metadata

import numpy as np
import pytest

from constraints import Hole
from teleop.cli.commands import COMMAND_GROUP
from teleop.cli.main import BUILT_IN, build_parser
from teleop.cli.robot_options import robot_from_arguments
from teleop.controller_specs import (
    CONTEXTS,
    CONTROLLER_SPECS,
    ControllerSpec,
    default_specs,
    make_controller,
    spec_names,
)
from teleop.robots import load_robot
from web import cli as web_cli


def run(*args: str, module: str = "teleop.cli",
        env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", module, *args], capture_output=True, text=True,
                          timeout=120, env=env)


def subcommand_parsers() -> dict[str, argparse.ArgumentParser]:
    """The parser behind ``teleop NAME --help`` for every subcommand (web: registered)."""
    (commands,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(commands.choices)


def option_blocks(help_text: str) -> list[str]:
    """Each option's entry in a help text (its flags and help), whitespace collapsed."""
    blocks: list[list[str]] = []
    current: list[str] | None = None
    for line in help_text.splitlines():
        if re.match(r"^  -", line):  # an option's first line
            current = [line]
            blocks.append(current)
        elif current is not None and line.startswith("   ") and line.strip():
            current.append(line)  # its help, continued
        else:  # blank line, section title or epilog: the block is over
            current = None
    return [" ".join(" ".join(block).split()) for block in blocks]


def test_version_is_the_installed_version():
    result = run("--version")
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == metadata.version("cjm-teleop")


def test_the_subcommands_are_the_documented_ones():
    assert set(subcommand_parsers()) == {"compare", "replay", "record", "scenarios", "robots",
                                         "bench", "sim", "sweep", "web"}
    (built_in,) = [a for a in build_parser(registered=False)._actions
                   if isinstance(a, argparse._SubParsersAction)]
    assert set(built_in.choices) == set(BUILT_IN)


def test_a_built_in_command_loads_no_registered_one():
    """``teleop scenarios`` neither imports web nor viser (the registered commands are
    loaded for themselves and for ``teleop --help`` only)."""
    code = ("import sys; from teleop.cli.main import main; code = main(['scenarios']); "
            "print(code, sorted(m for m in ('web', 'web.cli', 'viser') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[-1] == "0 []"


@pytest.mark.parametrize("command", sorted(subcommand_parsers()))
def test_every_subcommand_help_shows_each_option_default(command):
    result = run(command, "--help")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith(f"usage: teleop {command}")
    parser = subcommand_parsers()[command]
    assert parser.description and "\n" not in parser.description.strip()  # one line
    blocks = option_blocks(result.stdout)
    options = [a for a in parser._actions if a.option_strings
               and not isinstance(a, (argparse._HelpAction, argparse._VersionAction))]
    for action in options:
        flag = action.option_strings[-1]
        # the block starts with the action's flags ("--collisions, --no-collisions")
        (block,) = [b for b in blocks if re.match(rf"(?:-[\w-]+, )*{re.escape(flag)}(?![\w-])", b)]
        if action.required:
            continue  # no default to show
        assert "(default" in block, f"{command} {flag}: no default in {block!r}"
        if action.default is not None:
            shown = " ".join(str(action.default).split())
            assert f"(default: {shown})" in block, f"{command} {flag}: {block!r}"


def test_top_level_help_lists_each_subcommand_with_its_summary():
    result = run("--help")
    assert result.returncode == 0, result.stderr
    for name, parser in subcommand_parsers().items():
        assert re.search(rf"^\s+{name}\b", result.stdout, re.MULTILINE), name


def test_web_help_is_webs_own_and_python_m_web_works():
    through_teleop = run("web", "--help")
    direct = run("--help", module="web")
    assert through_teleop.returncode == 0 and direct.returncode == 0, direct.stderr
    assert direct.stdout.startswith("usage: python -m web")
    for option in ("--robot", "--ee-frame", "--constrained-link", "--link-axis", "--package-dirs",
                   "--q-home", "--controller", "--ghost", "--host", "--port"):
        assert option in through_teleop.stdout and option in direct.stdout, option
    assert "(default: 127.0.0.1)" in " ".join(through_teleop.stdout.split())


def test_web_with_a_missing_urdf_is_one_line_and_exit_2():
    result = run("web", "--robot", "/nonexistent.urdf")
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "/nonexistent.urdf" in lines[0], result.stderr


@pytest.mark.parametrize("args, message", [
    (["--robot", "sda10f", "--ee-frame", "nope"], "unknown ee_frame 'nope'"),
    (["--robot", "sda10f", "--q-home", "0,0,0"], "q_home must have size nq = 8"),
    (["--robot", "sda10f", "--link-axis", "0", "0", "0"], "link_axis must be non-zero"),
    (["--robot", "sda10f", "--controller", "qp:cplex"], "'cplex' is not available"),
])
def test_web_bad_values_are_one_line_and_exit_2(args, message, capsys):
    assert web_cli.main(args) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and message in err, err


def test_web_passes_the_urdf_options_to_load_robot(tmp_path):
    robot = load_robot("sda10f")
    args = web_cli.build_parser().parse_args([
        "--robot", str(robot.urdf_path), "--ee-frame", "arm_link_5_r", "--constrained-link",
        "arm_link_4_u", "--link-axis", "0", "0", "-2", "--package-dirs", f"{tmp_path},{tmp_path}/a",
        "--package-dirs", f"{tmp_path}/b", "--q-home=" + ",".join(map(str, robot.q_home)),
        "--locked-joints", "none"])
    loaded = robot_from_arguments(args, "sda10f")
    assert loaded.ee_frame == "arm_link_5_r" and loaded.constrained_link == "arm_link_4_u"
    np.testing.assert_allclose(loaded.link_axis, [0.0, 0.0, -1.0])
    np.testing.assert_allclose(loaded.q_home, robot.q_home)
    assert loaded.package_dirs == (str(tmp_path), f"{tmp_path}/a", f"{tmp_path}/b")


def test_web_is_registered_in_the_command_group_not_imported():
    """``teleop web`` comes from the installed metadata (pyproject.toml's entry point), and
    its parser is web's own options; tests/test_layers.py checks teleop never imports web."""
    (entry,) = [e for e in metadata.entry_points(group=COMMAND_GROUP) if e.name == "web"]
    assert entry.value == "web.cli:COMMAND" and entry.load() is web_cli.COMMAND
    registered = {a.dest for a in subcommand_parsers()["web"]._actions}
    assert registered == {a.dest for a in web_cli.build_parser()._actions}


PLUGIN = """
from teleop.cli.arguments import bounded
from teleop.cli.commands import Command


def add_arguments(parser):
    parser.add_argument("--name", default="world", help="whom to greet")
    parser.add_argument("--times", type=bounded(int, 1, 3), default=1, help="how many times")


def run(args, prog):
    for _ in range(args.times):
        print(f"{prog}: hello {args.name}")
    return 0


COMMAND = Command("greet someone", add_arguments, run, epilog="a command from a test")
NOT_A_COMMAND = print
"""


@pytest.fixture(scope="module")
def plugin_env(tmp_path_factory) -> dict[str, str]:
    """An environment whose ``sys.path`` holds a distribution registering three commands
    in the group: one that works, one whose module is missing, one that is not a Command."""
    folder = tmp_path_factory.mktemp("plugin")
    (folder / "teleop_test_greet.py").write_text(textwrap.dedent(PLUGIN))
    info = folder / "teleop_test_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: teleop-test-plugin\n"
                                   "Version: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{COMMAND_GROUP}]\n"
                                           "greet = teleop_test_greet:COMMAND\n"
                                           "broken = teleop_test_missing_module:COMMAND\n"
                                           "printer = teleop_test_greet:NOT_A_COMMAND\n"
                                           "scenarios = teleop_test_greet:COMMAND\n")
    path = [str(folder), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    return dict(os.environ, PYTHONPATH=os.pathsep.join(path))


def test_a_registered_command_runs_with_its_options_and_help(plugin_env):
    result = run("greet", "--name", "Ada", "--times", "2", env=plugin_env)
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines() == ["teleop greet: hello Ada"] * 2
    shown = run("greet", "--help", env=plugin_env)
    assert shown.stdout.startswith("usage: teleop greet") and "Greet someone." in shown.stdout
    assert "(default: world)" in shown.stdout and "a command from a test" in shown.stdout
    for bad, message in ((["--times", "9"], "argument --times: must be in [1, 3], got 9"),
                         (["--nope", "x"], "unrecognized arguments: --nope x")):
        refused = run("greet", *bad, env=plugin_env)
        assert refused.returncode == 2 and refused.stderr.splitlines() == [
            f"teleop greet: error: {message} (see 'teleop greet --help')"], refused.stderr


@pytest.mark.parametrize("name, reason", [
    ("broken", "cannot be loaded from teleop_test_missing_module:COMMAND (ModuleNotFoundError: "
               "No module named 'teleop_test_missing_module')"),
    ("printer", "cannot be loaded from teleop_test_greet:NOT_A_COMMAND (a "
                "builtin_function_or_method, not a Command of teleop.cli.commands)"),
])
def test_a_command_that_cannot_be_loaded_says_why_in_one_line(plugin_env, name, reason):
    for args in ([name], [name, "--any", "option"], [name, "--help"]):
        result = run(*args, env=plugin_env)
        assert result.returncode == 2 and result.stdout == "", result
        assert result.stderr.splitlines() == [f"teleop {name}: {reason}"], result.stderr
    listed = run("--help", env=plugin_env)
    assert listed.returncode == 0 and name in listed.stdout
    others = run("scenarios", env=plugin_env)  # the built-in commands still work...
    assert others.returncode == 0 and others.stdout.startswith("paper-hole"), others.stderr
    assert "hello" not in others.stdout  # ...and keep their names


# -- the controller registry ------------------------------------------------------------


def test_registry_is_one_ordered_table_with_defaults_per_context():
    names = spec_names()
    assert len(set(names)) == len(names) and names[0] == "cjm"
    assert all(spec.description and "\n" not in spec.description for spec in CONTROLLER_SPECS)
    for context in CONTEXTS:
        defaults = default_specs(context)
        assert defaults and list(defaults) == [n for n in names if n in defaults]  # table order
    parser = subcommand_parsers()
    assert parser["compare"].get_default("controllers") == ", ".join(default_specs("compare"))
    assert parser["bench"].get_default("controllers") == ", ".join(default_specs("bench"))
    with pytest.raises(ValueError, match="unknown context"):
        default_specs("nope")
    with pytest.raises(ValueError, match="unknown contexts"):
        ControllerSpec("x", "y", {"nope"})


@pytest.fixture(scope="module")
def sda10f():
    return load_robot("sda10f")


@pytest.mark.parametrize("spec", spec_names())
@pytest.mark.parametrize("with_hole", [False, True])
def test_every_registry_spec_builds_and_solves(spec, with_hole, sda10f):
    q = sda10f.q_home.copy()
    constraints = [Hole.on_link(sda10f, q, distance=0.08)] if with_hole else []
    controller = make_controller(spec, sda10f, constraints, dt=1e-3)
    qd = controller.solve(q, np.zeros(6))
    assert qd.shape == (sda10f.nv,) and np.all(np.isfinite(qd))


@pytest.mark.parametrize("spec, message", [
    ("lqr", "unknown controller 'lqr'"),
    ("cjm:nope", "unknown CJM variant 'nope'"),
    ("qp:cplex", r"'cplex' is not available .*installed: .*daqp"),
    ("mink:cplex", r"'cplex' is not available .*installed: .*daqp"),
])
def test_unknown_spec_raises_value_error(spec, message, sda10f):
    with pytest.raises(ValueError, match=message):
        make_controller(spec, sda10f)


def test_compare_says_each_run_it_finishes_when_stderr_is_no_terminal(tmp_path):
    """Output redirected: standard error still shows the runs going by, inside each a line
    at each tenth of its steps with the time left, then one line when it ends, the
    agreement run last."""
    result = run("compare", "--scenario", "paper-hole", "--duration", "0.02",
                 "--controllers", "cjm,qp:daqp", "--out", str(tmp_path), "--no-plots")
    assert result.returncode == 0, result.stderr
    lines = result.stderr.splitlines()
    runs = ["cjm", "qp:daqp", "joint velocities against cjm"]
    assert len(lines) == 10 * len(runs), result.stderr
    for index, name in enumerate(runs, start=1):
        own = lines[10 * (index - 1):10 * index]
        for tenth, line in enumerate(own[:-1], start=1):
            assert re.fullmatch(rf"paper-hole: {re.escape(name)} {10 * tenth}% \({2 * tenth}/20 "
                                r"steps, [0-9.]+ s, about [0-9]+ s left\)", line), line
        assert re.fullmatch(rf"paper-hole: {re.escape(name)} done \({index}/3, 20 steps in "
                            r"[0-9.]+ s\)", own[-1]), own[-1]


def test_compare_shows_a_bar_with_an_estimate_on_a_terminal():
    """On a terminal: tqdm's bar over the current run's steps (each controller's pass),
    named with the run and its place, with the run's time left (``<``)."""
    import io

    from teleop.experiments.compare import RunProgress

    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    console = Terminal()
    progress = RunProgress("paper-hole", ["cjm", "qp:daqp"], steps=50, console=console)
    progress.start("cjm")
    for step in range(50):
        progress.step(step)
    progress.start("qp:daqp")
    progress.step(0)
    progress.finish()
    progress.close()
    shown = console.getvalue()
    assert "paper-hole: cjm 1/2: 100%" in shown and "50/50" in shown
    assert "paper-hole: qp:daqp 2/2" in shown and "/100" not in shown
    assert re.search(r"\d\d:\d\d<\d\d:\d\d", shown), shown  # elapsed<remaining
    assert "done (" not in shown  # the lines are for consoles that are not terminals
