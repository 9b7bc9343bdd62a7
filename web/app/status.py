"""The status in words: what keeps each end effector from its target, and a control loop
falling behind (docs/design.md section 5.3)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from controllers import StepStatus
from teleop.loop import StepRecord
from teleop.loop.supervisor import Supervision

from .limits import FOLLOWING, ON_TARGET, STALLED_SPEED
from .plant import PortReading

#: the control loop is behind when it achieves less than this fraction of its rate
BEHIND_FRACTION = 0.95


@dataclass(frozen=True)
class Limitation:
    """What limits a robot now: the step status (it colours the EE-target line) and why,
    in words (what part of the target is short, why and what helps, docs/design.md
    section 20.4, the step's own words then in ``details``)."""

    status: str  # a StepStatus value
    words: str
    distance: float  # EE to target (m)
    details: str = ""  # the step's own words when ``words`` says it more plainly


def not_following(record: StepRecord, ee: int = 0) -> bool:
    """Whether EE ``ee`` moves towards its target at less than :data:`FOLLOWING` of the
    commanded speed (or hardly at all): something keeps it from the target."""
    desired = np.asarray(record.commanded_linear_velocities[ee])
    actual = np.asarray(record.actual_linear_velocities[ee])
    speed = float(np.linalg.norm(desired))
    if speed < STALLED_SPEED:
        return float(np.linalg.norm(actual)) < STALLED_SPEED
    return float(actual @ desired) / speed < FOLLOWING * speed


def describe_limitation(info, record: StepRecord | None, distance: float,
                        joint_names: list[str], refused: str = "", ee: int = 0) -> Limitation:
    """In words, what keeps EE ``ee`` (an index of ``robot.ee_frames``) from its target
    (``info`` the controller's last :class:`controllers.SolveInfo`, ``record`` the last
    measured tick, ``distance`` the EE-target distance in m)."""
    status = info.status.value if isinstance(info.status, StepStatus) else str(info.status)
    if refused:
        return Limitation("failed", f"command refused: {refused}", distance)
    if status == "failed":
        return Limitation(status, f"no command: {info.message or 'the controller failed'}",
                          distance)
    if status == "constraint_degraded":
        return Limitation(status, f"constraint degraded: {info.message}", distance)
    parts = []
    if distance > ON_TARGET and record is not None and not_following(record, ee):
        parts.append("target out of reach")
    if status == "least_squares" and info.message:
        parts.append(f"closest motion: {info.message}")  # it names the joints and the damping
    elif info.saturated_joints:
        names = [joint_names[i] for i in info.saturated_joints]
        parts.append(f"joint {', '.join(names)} at {'its limit' if len(names) == 1 else 'their limits'}")
    elif status == "least_squares":
        parts.append("closest motion")
    if status == "scaled":
        # floored: a scale of 0.9996 is slowed, not "slowed to 100 %"
        parts.append(f"slowed to {math.floor(100 * info.scale)} % by the joint limits")
    if not parts:
        parts.append(f"moving to the target ({1e3 * distance:.1f} mm away)"
                     if distance > ON_TARGET else "on target")
    return Limitation(status, "; ".join(parts), distance)


def behind_words(achieved_rate: float, rate: float) -> str:
    """The operator's warning when a loop asked for ``rate`` (Hz) achieves less than
    :data:`BEHIND_FRACTION` of it over the last second, else ``""``: the robot then moves
    slower than commanded and the measures stretch in time (docs/design.md section 5.3)."""
    if achieved_rate >= BEHIND_FRACTION * rate:
        return ""
    return (f"control loop behind: only {achieved_rate:.0f} of the {rate:.0f} Hz asked for "
            f"({100.0 * achieved_rate / rate:.0f} %); this machine is too busy for this rate")


def supervision_words(supervision: Supervision | None) -> str:
    """What the supervisor measured beyond tolerance at the sensed configuration and what
    it did, ``"measured: <constraint> 0.812 mm off (tolerance 0.1 mm); supervisor
    scaled the operator's motion to 79 % (...); target 0.310 mm from the operator's"``;
    ``""`` when all is within tolerance and it did nothing (docs/design.md 5.2)."""
    if supervision is None:
        return ""
    parts = ([f"measured: {supervision.breach}"] if supervision.breach else []) + (
        [supervision.words] if supervision.words else [])
    return "; ".join(parts)


def port_words(ports: list[PortReading]) -> str:
    """The wall's force at each port in words, in millinewtons (a gentle drag pushes with
    a few), ``"port force <id> 3.12 mN (tissue 3.1 µm)"``; ``""`` without a port
    (docs/design.md section 17.2)."""
    if not ports:
        return ""
    return "port force " + ", ".join(
        f"{port.id} {1e3 * port.magnitude:.2f} mN (tissue {1e6 * port.displacement:.1f} µm)"
        for port in ports)


def summary_words(limitation: Limitation) -> str:
    """The few plain words of what an end effector does, for the status line: the first
    reason :func:`describe_limitation` gives (its details stay in the full status), with
    how far the target is when it is not reached (docs/design.md section 5.3); for a
    part of the target that is short, that part and the action that helps (section 20.4)."""
    part, short, rest = limitation.words.partition(" short of the target: ")
    if short:  # a shortfall (docs/design.md 20.4): what is short and the action that helps
        return f"{part} short: {rest.rpartition('; ')[2]}"
    first = limitation.words.split(";")[0].split(":")[0].strip()
    if limitation.distance > ON_TARGET and "away" not in first:
        return f"{first}, {1e3 * limitation.distance:.1f} mm from the target"
    return first
