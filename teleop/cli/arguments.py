"""What every ``teleop`` command line shares (the built-in commands and those registered
from the layers above, :mod:`teleop.cli.commands`): a parser whose errors are one line, a
help formatter that shows each default, and the option types (docs/cli.md)."""

from __future__ import annotations

import argparse
from typing import Callable, NoReturn

from teleop.limits import MAX_COLLISION_DISTANCE_M, MAX_SPEED_M_S
from teleop.options import NumberRange


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Every option's help shows its default ("(default: ...)" appended unless the help
    already says it; nothing for required options); descriptions and epilogs keep their lines."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if "(default" in text or action.required:
            return text
        return super()._get_help_string(action)


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser, its errors one line on standard error (exit code 2): the
    program, the problem and where the help is, without the usage block.

    ``strict``: arguments it does not know are its own error (a subcommand's parser: the
    message names the subcommand, not ``teleop``). ``unavailable``: why this subcommand
    cannot run; parsing it then prints that one line and exits 2, whatever the arguments
    (a registered command that could not be loaded)."""

    def __init__(self, *args, strict: bool = False, unavailable: str | None = None,
                 **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.strict = strict
        self.unavailable = unavailable

    def parse_known_args(self, args=None, namespace=None):
        if self.unavailable is not None:
            self.exit(2, f"{self.prog}: {self.unavailable}\n")
        namespace, extras = super().parse_known_args(args, namespace)
        if self.strict and extras:
            self.error(f"unrecognized arguments: {' '.join(extras)}")
        return namespace, extras

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see '{self.prog} --help')\n")


def one_line(error: Exception | str) -> str:
    """An error's message on one line (a message never spreads over several)."""
    return " ".join(str(error).split())


def sentence(summary: str) -> str:
    """A command's one-line summary as its description: capitalised, a full stop."""
    return summary[0].upper() + summary[1:] + "."


def csv_list(text: str) -> list[str]:
    """``"a, b,c"`` -> ``["a", "b", "c"]`` (argparse type)."""
    items = [item.strip() for item in text.split(",") if item.strip()]
    if not items:
        raise argparse.ArgumentTypeError("expected a comma-separated list")
    return items


def numbers(text: str) -> list[float]:
    """``"0, -1.2,0.5"`` -> ``[0.0, -1.2, 0.5]`` (argparse type)."""
    try:
        return [float(item) for item in csv_list(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated numbers, got {text!r}") from None


def bounded(kind: type[float] | type[int], minimum: float, maximum: float | None = None, *,
            inclusive_minimum: bool = True, unit: str = "") -> Callable[[str], float]:
    """An argparse type: a finite ``kind`` (``float`` or ``int``) in ``[minimum, maximum]``
    (``(minimum, ...`` unless ``inclusive_minimum``; no maximum when None), its range named
    in the message with its ``unit`` (:class:`teleop.options.NumberRange`, the words every
    front end uses)."""
    return NumberRange(kind, minimum, maximum, inclusive_minimum, unit).parse


#: A finite number > 0.
positive = bounded(float, 0.0, inclusive_minimum=False)


#: The collision damper's options: (option, the CollisionAvoidance field, factor to SI,
#: help) (docs/design.md section 18.3)
DAMPER_OPTIONS = (
    ("--safety-distance", "safety_distance", 1e-3,
     f"d_s: the distance every pair is kept apart, mm in [0, {MAX_COLLISION_DISTANCE_M * 1e3:g}] "
     "(default: 5)"),
    ("--detection-distance", "detection_distance", 1e-3,
     f"d_i > d_s: pairs closer than this get their row, mm in [0, "
     f"{MAX_COLLISION_DISTANCE_M * 1e3:g}] (default: 50)"),
    ("--approach-speed", "approach_speed", 1.0,
     f"xi: how fast a pair may close at d_i (0 at d_s), m/s in (0, {MAX_SPEED_M_S:g}] "
     "(default: 0.5)"))
millimetres = bounded(float, 0.0, MAX_COLLISION_DISTANCE_M * 1e3, unit="mm")
speed = bounded(float, 0.0, MAX_SPEED_M_S, inclusive_minimum=False, unit="m/s")


def add_damper_options(group: argparse._ActionsContainer) -> None:
    """``--safety-distance``, ``--detection-distance``, ``--approach-speed`` (left out: None)."""
    for option, _, factor, help_text in DAMPER_OPTIONS:
        group.add_argument(option, type=millimetres if factor == 1e-3 else speed,
                           metavar="MM" if factor == 1e-3 else "M_PER_S", help=help_text)


def damper_settings(args: argparse.Namespace) -> dict[str, tuple[str, float]]:
    """The damper options given: ``CollisionAvoidance`` field -> (option, value in SI)."""
    return {name: (option, getattr(args, name) * factor)
            for option, name, factor, _ in DAMPER_OPTIONS if getattr(args, name) is not None}
