"""The supervisor's command-line options (docs/cli.md, docs/design.md 5.2): the measured
status's tolerances, the warning and hold levels, or a supervisor that only measures."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from teleop.limits import MAX_SUPERVISOR_ERROR_M, MAX_SUPERVISOR_FORCE_N, MAX_SUPERVISOR_RAMP_S
from teleop.loop.supervisor import SupervisorConfig

from .arguments import bounded

#: the defaults, shown in the options' help
DEFAULT = SupervisorConfig()


#: a time of the scale's ramp: seconds in [0, MAX_SUPERVISOR_RAMP_S] (0: at once)
seconds = bounded(float, 0.0, MAX_SUPERVISOR_RAMP_S, unit="s")
#: a constraint error (mm) and a port force (N) the supervisor compares with: > 0, bounded
millimetres = bounded(float, 0.0, 1e3 * MAX_SUPERVISOR_ERROR_M, inclusive_minimum=False,
                      unit="mm")
newtons = bounded(float, 0.0, MAX_SUPERVISOR_FORCE_N, inclusive_minimum=False, unit="N")


def _pair(text: str, first: Callable[[str], float] = millimetres,
          second: Callable[[str], float] | None = None) -> tuple[float, float]:
    """``"A,B"`` -> two finite numbers, parsed by ``first`` and ``second`` (by default the
    same; argparse type)."""
    parts = text.split(",")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"expected two numbers A,B, got {text!r}")
    return first(parts[0].strip()), (second or first)(parts[1].strip())


def _tolerances(text: str) -> tuple[float, float]:
    """``"MM,N"``: a constraint error and a port force (argparse type)."""
    return _pair(text, millimetres, newtons)


def _forces(text: str) -> tuple[float, float]:
    """``"WARN_N,HOLD_N"`` (argparse type)."""
    return _pair(text, newtons)


def _times(text: str) -> tuple[float, float]:
    """``"FALL_S,RELEASE_S"`` (argparse type)."""
    return _pair(text, seconds)


def add_supervisor_options(parser: argparse.ArgumentParser) -> None:
    """``--measured-tolerance``, ``--supervisor-error``, ``--supervisor-force``,
    ``--supervisor-ramp``, ``--no-supervisor`` in a group of their own (left out: the
    defaults)."""
    group = parser.add_argument_group(
        "the supervisor", "measures each constraint's error at the sensed configuration (and "
        "the port force on the mujoco plant) every period: a step is ok only within tolerance; "
        "it scales the operator's motion from 1 at the warning level to 0 at the hold level, "
        "where the target is held (docs/design.md section 5.2)")
    group.add_argument("--measured-tolerance", type=_tolerances, metavar="MM,N",
                       help="a measured constraint error (mm) or port force (N) above these: "
                       f"the step is not ok (default: {1e3 * DEFAULT.tolerance:g},"
                       f"{DEFAULT.force_tolerance:g})")
    group.add_argument("--supervisor-error", type=_pair, metavar="WARN_MM,HOLD_MM",
                       help="measured constraint error where the operator's motion starts to "
                       f"be scaled down, and where the target is held (default: "
                       f"{1e3 * DEFAULT.error_warn:g},"
                       f"{1e3 * DEFAULT.error_hold:g})")
    group.add_argument("--supervisor-force", type=_forces, metavar="WARN_N,HOLD_N",
                       help="the same for the measured port force (default: "
                       f"{DEFAULT.force_warn:g},{DEFAULT.force_hold:g})")
    group.add_argument("--supervisor-ramp", type=_times, metavar="FALL_S,RELEASE_S",
                       help="the scale on the operator's motion falls from 1 to 0 and rises "
                       "back in no less than these, 0: at once (default: "
                       f"{DEFAULT.fall_time:g},{DEFAULT.release_time:g})")
    group.add_argument("--no-supervisor", action="store_true",
                       help="measure and flag, never scale the operator's motion nor hold "
                       "the target")


def supervisor_choice(args: argparse.Namespace) -> SupervisorConfig:
    """The :class:`SupervisorConfig` the options ask for (``ValueError`` naming the field
    when a warning level is not below its hold level)."""
    tolerance = args.measured_tolerance or (1e3 * DEFAULT.tolerance, DEFAULT.force_tolerance)
    error = args.supervisor_error or (1e3 * DEFAULT.error_warn, 1e3 * DEFAULT.error_hold)
    force = args.supervisor_force or (DEFAULT.force_warn, DEFAULT.force_hold)
    ramp_times = args.supervisor_ramp or (DEFAULT.fall_time, DEFAULT.release_time)
    return SupervisorConfig(tolerance=1e-3 * tolerance[0], error_warn=1e-3 * error[0],
                            error_hold=1e-3 * error[1], force_tolerance=tolerance[1],
                            force_warn=force[0], force_hold=force[1], fall_time=ramp_times[0],
                            release_time=ramp_times[1], acting=not args.no_supervisor)
