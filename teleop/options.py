"""The options several front ends share, each defined once (docs/cli.md): its name, range,
unit, placeholder and help, and the one validator every front end runs.

``teleop compare``, ``replay``, ``record`` and ``bench`` (:mod:`teleop.cli`), ``teleop web``
(:mod:`web.cli`) and ``teleop sweep``, its command line and its spec file
(:mod:`teleop.experiments.sweep.spec`), read the options below through
:class:`SharedOption`: as an argparse type (:meth:`SharedOption.parse`, text) or as a value
of a spec (:meth:`SharedOption.check`, a JSON number), both with the words of
:meth:`NumberRange.problem`, so a bad value is refused with the same message wherever it
is given. The bounds are those of :mod:`teleop.limits`.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any

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
    MAX_PAYLOAD_KG,
    MAX_POSE_GAIN,
    MAX_RATE_HZ,
    MAX_TIME_CONSTANT_S,
    MAX_TROCAR_SHIFT_M,
    MAX_WALL_STIFFNESS,
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


@dataclass(frozen=True)
class SharedOption:
    """An option several front ends take: ``name`` its field (``"rate"``, the option
    ``--rate``), its :class:`NumberRange`, its placeholder and what it is (``help``,
    without its range or default, which :meth:`help_text` adds)."""

    name: str
    range: NumberRange
    metavar: str
    help: str

    @property
    def option(self) -> str:
        """``--`` and the name, dashed: ``--joint-time-constant``."""
        return "--" + self.name.replace("_", "-")

    def parse(self, text: str) -> Any:
        """The argparse type (:meth:`NumberRange.parse`)."""
        return self.range.parse(text)

    def check(self, value: Any, name: str | None = None) -> Any:
        """A value from a spec or a keyword (:meth:`NumberRange.check`), named ``name``
        (default: the field's name)."""
        return self.range.check(value, self.name if name is None else name)

    def help_text(self) -> str:
        """What the option is and its range, for an argparse help."""
        return f"{self.help}, {self.range.bounds()}"

    def add_to(self, group: argparse._ActionsContainer, default: Any = None,
               left_out: str = "") -> argparse.Action:
        """Add the option to ``group`` (an argparse parser or group) with the value
        ``default`` when it is left out (the help shows it); or, with ``default`` None,
        ``left_out`` says in the help what leaving it out means."""
        text = self.help_text() if default is not None else \
            f"{self.help_text()} (default: {left_out})"
        return group.add_argument(self.option, dest=self.name, type=self.parse,
                                  default=default, metavar=self.metavar, help=text)


def _positive(maximum: float, unit: str) -> NumberRange:
    return NumberRange(float, 0.0, maximum, inclusive_minimum=False, unit=unit)


RATE = SharedOption("rate", _positive(MAX_RATE_HZ, "Hz"), "HZ", "control rate")
DURATION = SharedOption("duration", _positive(MAX_DURATION_S, "s"), "S", "seconds to run")
SEED = SharedOption("seed", NumberRange(int, 0, MAX_SEED), "SEED",
                    "seed of the encoder noise, the calibration error and the random "
                    "variations (each its own stream)")
PAYLOAD = SharedOption("payload", NumberRange(float, 0.0, MAX_PAYLOAD_KG, unit="kg"), "KG",
                       "mass at each EE the plant carries and the gravity compensation and "
                       "the controllers do not know of (mujoco)")
WALL_STIFFNESS = SharedOption(
    "wall_stiffness", NumberRange(float, 0.0, MAX_WALL_STIFFNESS / 1e3, unit="N/mm"),
    "N_PER_MM", "lateral stiffness of the abdominal wall at every hole (mujoco)")
KP = SharedOption("kp", _positive(MAX_POSE_GAIN, "1/s"), "K", "pose-error gain K_p of the loop")
CONSTRAINT_GAIN = SharedOption(
    "constraint_gain", NumberRange(float, 0.0, MAX_CONSTRAINT_GAIN, unit="1/s"), "K",
    "drift-feedback gain of every constraint, K dt < 2 (1 for a barrier)")
JERK_LIMIT = SharedOption(
    "jerk_limit", _positive(MAX_JERK, "rad/s^3"), "RAD_PER_S3",
    "a jerk limit every controller keeps on every joint (docs/design.md section 8.5; with "
    "the acceleration limits); a Franka's joints refuse 3750-10000")
ENCODER_NOISE = SharedOption(
    "encoder_noise", NumberRange(float, 0.0, MAX_ENCODER_NOISE_RAD, unit="rad"), "RAD",
    "std of the Gaussian noise on each measured joint, every period")
LATENCY = SharedOption("latency", NumberRange(int, 0, MAX_LATENCY_PERIODS), "PERIODS",
                       "control periods between a command and the joints")
JOINT_TIME_CONSTANT = SharedOption(
    "joint_time_constant", NumberRange(float, 0.0, MAX_TIME_CONSTANT_S, unit="s"), "S",
    "first-order response of the joint velocities to their command")
CALIBRATION_POSITION = SharedOption(
    "calibration_error_mm", NumberRange(float, 0.0, MAX_CALIBRATION_POSITION_STD_M * 1e3,
                                        unit="mm"),
    "MM", "std of each joint placement's translation error")
CALIBRATION_ROTATION = SharedOption(
    "calibration_error_mrad", NumberRange(float, 0.0, MAX_CALIBRATION_ROTATION_STD_RAD * 1e3,
                                          unit="mrad"),
    "MRAD", "std of each joint placement's rotation error")
TROCAR_SHIFT = SharedOption(
    "trocar_shift", NumberRange(float, 0.0, MAX_TROCAR_SHIFT_M, unit="m"), "M",
    "slide each constraint along its link by U(-M, M) m, still holding where it starts")
PATH_AMPLITUDE = SharedOption(
    "path_amplitude", NumberRange(float, 0.0, MAX_PATH_AMPLITUDE_M, unit="m"), "M",
    "add to each EE target a smooth random path (three sinusoids, 0.05-0.5 Hz, from rest) "
    "of at most M m")

#: What ``--acceleration-limits`` / ``--no-acceleration-limits`` (a sweep's
#: ``acceleration_limits``) say.
ACCELERATION_LIMITS_HELP = ("the controllers keep the robot's joint acceleration limits "
                            "(docs/design.md section 8.4); --no-acceleration-limits: none")

#: Every shared number option, by its field's name.
SHARED_OPTIONS: dict[str, SharedOption] = {option.name: option for option in (
    RATE, DURATION, SEED, PAYLOAD, WALL_STIFFNESS, KP, CONSTRAINT_GAIN, JERK_LIMIT,
    ENCODER_NOISE, LATENCY, JOINT_TIME_CONSTANT, CALIBRATION_POSITION, CALIBRATION_ROTATION,
    TROCAR_SHIFT, PATH_AMPLITUDE)}
