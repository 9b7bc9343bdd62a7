"""The options several front ends share, each declared once (docs/cli.md): its name, what
its value is (a range and unit, a choice, a text, names), its placeholder, its help and the
commands that take it, and the one validator every front end runs.

``teleop compare``, ``replay``, ``record`` and ``bench`` (:mod:`teleop.cli`), ``teleop web``
(:mod:`web.cli`) and ``teleop sweep``, its command line and its spec file
(:mod:`teleop.experiments.sweep.spec`), read the options below through
:class:`SharedOption`: as an argparse type (:meth:`SharedOption.parse`, text) or as a value
of a spec, a session or a keyword (:meth:`SharedOption.check`), both with the words of
the value's ``problem``, so a bad value is refused with the same message wherever it is
given. The plants' options are declared the same way in :mod:`teleop.plants.options`. The
bounds are those of :mod:`teleop.limits`.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from numbers import Integral, Real
from typing import Any, Protocol

from constraints.validation import short_repr
from teleop.limits import (
    MAX_CALIBRATION_POSITION_STD_M,
    MAX_CALIBRATION_ROTATION_STD_RAD,
    MAX_CONSTRAINT_GAIN,
    MAX_DURATION_S,
    MAX_ENCODER_NOISE_RAD,
    MAX_JERK,
    MAX_LATENCY_PERIODS,
    MAX_PATH_AMPLITUDE_M,
    MAX_POSE_GAIN,
    MAX_RATE_HZ,
    MAX_TIME_CONSTANT_S,
    MAX_TROCAR_SHIFT_M,
)

#: The plants a run can choose, by name (``--plant``; built by
#: :class:`teleop.plants.PlantChoice`).
PLANT_KINDS = ("kinematic", "mujoco", "ros2")

#: The plants simulated in this process (many runs at once, each its own robot: a sweep's
#: cells, ``teleop sim``).
SIMULATED_PLANT_KINDS = ("kinematic", "mujoco")

#: The largest seed: SQLite's and NumPy's 64-bit integers.
MAX_SEED = 2**63 - 1


def _shown(bound: float) -> str:
    return f"{bound:g}" if isinstance(bound, float) else str(bound)


@dataclass(frozen=True)
class NumberRange:
    """A finite number of ``kind`` (``float`` or ``int``) in ``[minimum, maximum]``
    (``(minimum, ...`` unless ``inclusive_minimum``; no maximum when None), in ``unit``."""

    kind: type[float] | type[int]
    minimum: float
    maximum: float | None = None
    inclusive_minimum: bool = True
    unit: str = ""

    @property
    def noun(self) -> str:
        """``"an integer"`` or ``"a number"``."""
        return "an integer" if self.kind is int else "a number"

    def bounds(self) -> str:
        """The range in words: ``"in (0, 10000] Hz"``, ``"a finite number >= 0"``."""
        if self.maximum is None:
            text = (f"{'' if self.kind is int else 'a finite number '}"
                    f"{'>=' if self.inclusive_minimum else '>'} {_shown(self.minimum)}")
        else:
            text = (f"in {'[' if self.inclusive_minimum else '('}{_shown(self.minimum)}, "
                    f"{_shown(self.maximum)}]")
        return f"{text} {self.unit}" if self.unit else text

    def problem(self, value: Any) -> str | None:
        """What is wrong with ``value`` (``"must be in (0, 10000] Hz, got 0"``), or None:
        not a number of the kind (a boolean, a string, a float for an integer), not
        finite, or out of range."""
        integral = isinstance(value, Integral) and not isinstance(value, bool)
        if not (integral if self.kind is int else isinstance(value, Real)) \
                or isinstance(value, bool):
            return f"must be {self.noun}, got {short_repr(value)}"
        try:
            number = float(value)
        except OverflowError:  # an integer beyond a float's range
            number = math.inf
        above = self.minimum <= number if self.inclusive_minimum else self.minimum < number
        if math.isfinite(number) and above and (self.maximum is None or number <= self.maximum):
            return None
        shown = str(value) if integral else f"{number:g}"
        return f"must be {self.bounds()}, got {shown}"

    def check(self, value: Any, name: str) -> Any:
        """``value`` as the kind (a float, or the integer itself) when it is in range,
        else ``ValueError`` naming ``name``: ``"rate must be in (0, 10000] Hz, got 0"``."""
        problem = self.problem(value)
        if problem is not None:
            raise ValueError(f"{name} {problem}")
        return value if self.kind is int else float(value)

    def parse(self, text: str) -> Any:
        """An argparse type: the number ``text`` holds, else ``ArgumentTypeError`` with
        the words of :meth:`problem` (argparse names the option)."""
        try:
            value = self.kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {self.noun}, got {text!r}") from None
        problem = self.problem(value)
        if problem is not None:
            raise argparse.ArgumentTypeError(problem)
        return value

    def argparse_keywords(self) -> dict[str, Any]:
        return {"type": self.parse}


class ValueKind(Protocol):
    """What an option's value is: how a text (the command line) and a value (a spec, a
    session, a keyword) are read, with the same words for the same problem."""

    def bounds(self) -> str:
        """What it takes, in words (``"in (0, 10000] Hz"``; empty: nothing to add)."""
        ...

    def problem(self, value: Any) -> str | None:
        """What is wrong with ``value``, or None."""
        ...

    def check(self, value: Any, name: str) -> Any:
        """``value`` normalised, else ``ValueError`` naming ``name``."""
        ...

    def parse(self, text: str) -> Any:
        """The value a command line's ``text`` holds, else ``ArgumentTypeError``."""
        ...

    def argparse_keywords(self) -> dict[str, Any]:
        """How argparse reads the text: ``type`` (or ``choices``)."""
        ...


def _checked(kind: ValueKind, value: Any, name: str) -> None:
    problem = kind.problem(value)
    if problem is not None:
        raise ValueError(f"{name} {problem}")


class _Word:
    """A text value taken as it is: no bounds to name, checked by its ``problem``."""

    def problem(self, value: Any) -> str | None:
        raise NotImplementedError

    def bounds(self) -> str:
        return ""

    def check(self, value: Any, name: str) -> str:
        _checked(self, value, name)
        return value

    def parse(self, text: str) -> str:
        problem = self.problem(text)
        if problem is not None:
            raise argparse.ArgumentTypeError(problem)
        return text

    def argparse_keywords(self) -> dict[str, Any]:
        return {"type": self.parse}


@dataclass(frozen=True)
class Choice(_Word):
    """One of ``values`` (names)."""

    values: tuple[str, ...]

    def problem(self, value: Any) -> str | None:
        if isinstance(value, str) and value in self.values:
            return None
        return f"must be one of {', '.join(self.values)}, got {short_repr(value)}"

    def argparse_keywords(self) -> dict[str, Any]:
        """argparse's own ``choices`` (its message lists them)."""
        return {"choices": self.values}


@dataclass(frozen=True)
class Text(_Word):
    """A non-empty text without spaces at its ends (a topic, a namespace): what it means
    is checked where it is used (a ROS 2 topic by :mod:`teleop.plants.ros2.names`)."""

    def problem(self, value: Any) -> str | None:
        if isinstance(value, str) and value.strip() and value == value.strip():
            return None
        return f"must be a non-empty text, got {short_repr(value)}"


@dataclass(frozen=True)
class Names:
    """One or more names: ``"a, b"`` on a command line, ``["a", "b"]`` in a file; the
    value a tuple of the names."""

    def bounds(self) -> str:
        return "comma-separated"

    def problem(self, value: Any) -> str | None:
        if isinstance(value, (list, tuple)) and value \
                and all(isinstance(item, str) and item.strip() for item in value):
            return None
        return f"must be a list of one or more names, got {short_repr(value)}"

    def check(self, value: Any, name: str) -> tuple[str, ...]:
        _checked(self, value, name)
        return tuple(item.strip() for item in value)

    def parse(self, text: str) -> tuple[str, ...]:
        names = tuple(item.strip() for item in text.split(",") if item.strip())
        if not names:
            raise argparse.ArgumentTypeError(f"must be one or more comma-separated names, "
                                             f"got {text!r}")
        return names

    def argparse_keywords(self) -> dict[str, Any]:
        return {"type": self.parse}


#: The commands that take shared options (``teleop sim`` only the ROS 2 robot's).
COMPARE, REPLAY, RECORD, BENCH, WEB, SWEEP, SIM = (
    "compare", "replay", "record", "bench", "web", "sweep", "sim")
COMMANDS = (COMPARE, REPLAY, RECORD, BENCH, WEB, SWEEP, SIM)
#: The commands that run controllers on a robot, alone (not a grid of them).
RUNS = frozenset((COMPARE, REPLAY, RECORD, BENCH, WEB))


@dataclass(frozen=True)
class SharedOption:
    """An option several front ends take, declared once: ``name`` its field (``"rate"``,
    the option ``--rate``), what its value is (``range``: a :class:`NumberRange`,
    :class:`Choice`, :class:`Text` or :class:`Names`), its placeholder, what it is
    (``help``, without its range or default, which :meth:`help_text` adds) and the
    ``commands`` that take it (:data:`COMMANDS`; a test checks each parser against it).
    ``default``: the value a run takes when nothing gives one (a sweep's cell leaves it out
    of its key); None: ``left_out`` says what the run does instead."""

    name: str
    range: ValueKind
    metavar: str | None
    help: str
    commands: frozenset[str] = field(default=frozenset())
    default: Any = None
    left_out: str = ""

    def default_words(self) -> str:
        """What leaving the option out means, in words (``"1000"``, ``"none"``)."""
        return self.left_out if self.default is None else f"{self.default:g}"

    @property
    def option(self) -> str:
        """``--`` and the name, dashed: ``--joint-time-constant``."""
        return "--" + self.name.replace("_", "-")

    def parse(self, text: str) -> Any:
        """The argparse type: the value ``text`` holds, else ``ArgumentTypeError`` with
        the words of the range's ``problem`` (argparse names the option)."""
        return self.range.parse(text)

    def check(self, value: Any, name: str | None = None) -> Any:
        """A value from a spec, a session or a keyword, normalised, else ``ValueError``
        naming ``name`` (default: the field's name) with the same words as :meth:`parse`."""
        return self.range.check(value, self.name if name is None else name)

    def help_text(self) -> str:
        """What the option is and its range, for an argparse help."""
        bounds = self.range.bounds()
        return f"{self.help}, {bounds}" if bounds else self.help

    def add_to(self, group: argparse._ActionsContainer, default: Any = None,
               left_out: str = "") -> argparse.Action:
        """Add the option to ``group`` (an argparse parser or group) with the value
        ``default`` when it is left out (the help shows it); or, with ``default`` None,
        ``left_out`` says in the help what leaving it out means."""
        text = self.help_text() if default is not None else \
            f"{self.help_text()} (default: {left_out})"
        return group.add_argument(self.option, dest=self.name, default=default,
                                  metavar=self.metavar, help=text,
                                  **self.range.argparse_keywords())


def _positive(maximum: float, unit: str) -> NumberRange:
    return NumberRange(float, 0.0, maximum, inclusive_minimum=False, unit=unit)


RATE = SharedOption("rate", _positive(MAX_RATE_HZ, "Hz"), "HZ", "control rate",
                    frozenset((COMPARE, REPLAY, RECORD, WEB, SWEEP)), 1000.0)
DURATION = SharedOption("duration", _positive(MAX_DURATION_S, "s"), "S", "seconds to run",
                        frozenset((COMPARE, REPLAY, RECORD, SWEEP)),
                        left_out="each scenario's or session's")
SEED = SharedOption("seed", NumberRange(int, 0, MAX_SEED), "SEED",
                    "seed of the encoder noise, the calibration error and the random "
                    "variations (each its own stream)",
                    frozenset((COMPARE, REPLAY)), 0)  # a sweep takes seeds: a count or a list
#: the options of a run's controllers and its imperfect robot: compare, replay and sweep
CONTROLLED = frozenset((COMPARE, REPLAY, SWEEP))
KP = SharedOption("kp", _positive(MAX_POSE_GAIN, "1/s"), "K", "pose-error gain K_p of the loop",
                  CONTROLLED, 20.0)
CONSTRAINT_GAIN = SharedOption(
    "constraint_gain", NumberRange(float, 0.0, MAX_CONSTRAINT_GAIN, unit="1/s"), "K",
    "drift-feedback gain of every constraint, K dt < 2 (1 for a barrier)", CONTROLLED,
    left_out="each constraint's own")
JERK_LIMIT = SharedOption(
    "jerk_limit", _positive(MAX_JERK, "rad/s^3"), "RAD_PER_S3",
    "a jerk limit every controller keeps on every joint (docs/design.md section 8.5; with "
    "the acceleration limits); a Franka's joints refuse 3750-10000",
    frozenset((COMPARE, REPLAY, WEB, SWEEP)), left_out="none")
ENCODER_NOISE = SharedOption(
    "encoder_noise", NumberRange(float, 0.0, MAX_ENCODER_NOISE_RAD, unit="rad"), "RAD",
    "std of the Gaussian noise on each measured joint, every period", CONTROLLED, 0.0)
LATENCY = SharedOption("latency", NumberRange(int, 0, MAX_LATENCY_PERIODS), "PERIODS",
                       "control periods between a command and the joints", CONTROLLED, 0)
JOINT_TIME_CONSTANT = SharedOption(
    "joint_time_constant", NumberRange(float, 0.0, MAX_TIME_CONSTANT_S, unit="s"), "S",
    "first-order response of the joint velocities to their command", CONTROLLED, 0.0)
CALIBRATION_POSITION = SharedOption(
    "calibration_error_mm", NumberRange(float, 0.0, MAX_CALIBRATION_POSITION_STD_M * 1e3,
                                        unit="mm"),
    "MM", "std of each joint placement's translation error", default=0.0)
CALIBRATION_ROTATION = SharedOption(
    "calibration_error_mrad", NumberRange(float, 0.0, MAX_CALIBRATION_ROTATION_STD_RAD * 1e3,
                                          unit="mrad"),
    "MRAD", "std of each joint placement's rotation error", default=0.0)
TROCAR_SHIFT = SharedOption(
    "trocar_shift", NumberRange(float, 0.0, MAX_TROCAR_SHIFT_M, unit="m"), "M",
    "slide each constraint along its link by U(-M, M) m, still holding where it starts",
    CONTROLLED, 0.0)
PATH_AMPLITUDE = SharedOption(
    "path_amplitude", NumberRange(float, 0.0, MAX_PATH_AMPLITUDE_M, unit="m"), "M",
    "add to each EE target a smooth random path (three sinusoids, 0.05-0.5 Hz, from rest) "
    "of at most M m", CONTROLLED, 0.0)

#: What ``--acceleration-limits`` / ``--no-acceleration-limits`` (a sweep's
#: ``acceleration_limits``) say.
ACCELERATION_LIMITS_HELP = ("the controllers keep the robot's joint acceleration limits "
                            "(docs/design.md section 8.4); --no-acceleration-limits: none")

#: Every shared option of a run, by its field's name (the plants' own:
#: :data:`teleop.plants.options.PLANT_OPTIONS`). The calibration error's two are one
#: option, ``--calibration-error MM,MRAD``, and two fields of a sweep's spec.
SHARED_OPTIONS: dict[str, SharedOption] = {option.name: option for option in (
    RATE, DURATION, SEED, KP, CONSTRAINT_GAIN, JERK_LIMIT,
    ENCODER_NOISE, LATENCY, JOINT_TIME_CONSTANT, CALIBRATION_POSITION, CALIBRATION_ROTATION,
    TROCAR_SHIFT, PATH_AMPLITUDE)}
