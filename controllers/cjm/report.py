"""What a CJM step reports, and the one function that words it (docs/design.md section 16).

Both backends end a step with a :class:`StepReport`: the status, the figures
(``sigma_min``, damping, scale, residual, the joints and barriers involved) and the
events that explain it, in the order they happened. :func:`solve_info` turns it into
the :class:`controllers.base.SolveInfo` every controller exposes, its message worded by
:func:`report_message`, where the messages are written and nowhere else.
"""

from __future__ import annotations

from enum import IntEnum
from dataclasses import dataclass
from typing import Mapping, Sequence

from constraints.collision import CollisionRows

from ..base import (NON_FINITE_NOTE, SolveInfo, StepStatus, clipped_note, residual_note,
                    with_note)
from ..linalg import RANK_TOLERANCE


class Event(IntEnum):
    """What happened in a step and the figures it carries as ``(a, b, c)``; the C++
    ``cjm::Event`` (``_step/report.hpp``'s ``CJM_EVENTS``) has the same names and codes but
    ``PAPER_FORM_UNDEFINED`` and ``LINEAR_ALGEBRA_ERROR``, which Python alone records
    (:func:`code_mismatches` compares them when the extension is imported)."""

    PRE_CHAIN_SINGULAR = 1  # the analytical form handed over to the general form
    TASK_RESIDUAL = 2       # a: damping, b: twist residual
    CONFLICT = 3            # a: rank, b: rows, c: least-squares residual
    NO_FREE_JOINT = 4
    ROWS_SCALED = 5         # a: the rows' scale
    TASK_MISSED = 6         # a: sigma_min, b: damping; the joints: saturation_joints
    TASK_SCALED = 7         # a: limiting joint, b: task scale
    CLIPPED = 8             # a: largest change; the joints: saturated_joints
    RESIDUAL = 9            # a: equality residual
    NO_CONVERGENCE = 10     # failed: the SVD did not converge
    NON_FINITE = 11         # failed: the command came out non-finite
    PAPER_FORM_UNDEFINED = 12  # a = 0: the paper's 1/a form gave way to the null-space form
    LINEAR_ALGEBRA_ERROR = 13  # failed: a LAPACK error (StepReport.error says which)
    PAIR_CONFLICT = 14      # a: collision row, b: shortfall (m/s) below the equality rows


#: Event by its code (the C++ report's event log holds codes)
EVENT_BY_CODE = {event.value: event for event in Event}
#: SolveInfo.method by its code in the C++ report (0: none yet, the C++ ``none``)
METHODS = ("", "analytical", "general", "saturated")
#: the C++ name of METHODS[0], the step that has not chosen a method yet
NO_METHOD = "none"

PRE_CHAIN_SINGULAR_NOTE = "pre-constraint chain singular: general form used"
NO_FREE_JOINT_NOTE = "the constraints leave no joint free for the task"
PAPER_FORM_NOTE = "a = 0, where the paper's 1/a form is singular: null-space form used"
#: the message of a step whose SVD did not converge (the command is zero)
NO_CONVERGENCE_NOTE = "LinAlgError: SVD did not converge (Jacobi sweeps)"


@dataclass(slots=True)
class StepReport:
    """One step of either backend: its status, figures and events (in order).

    The compiled step builds it in one call from the C++ report; the Python step fills
    it as it runs (:meth:`event`, :meth:`fail`), starting from the defaults below, which
    are an ``ok`` step's. ``saturation_joints``: the joints a saturated step held at a
    limit when it missed the task (the ``TASK_MISSED`` event names them); ``error``: the
    text of a ``LINEAR_ALGEBRA_ERROR``. With collision avoidance, ``collision`` holds the
    step's :class:`~constraints.collision.CollisionRows` and ``active_pairs`` the indices
    of its rows held at their bound (else None and ()). ``dropped_events``: the events
    the compiled step's fixed record had no room for (past its last row; a failure takes
    that row): the message says how many; the status never depends on the record.
    """

    status: StepStatus = StepStatus.OK
    method: str = ""
    sigma_min: float = float("nan")
    damping: float = 0.0
    scale: float = 1.0
    equality_residual: float = 0.0
    saturated_joints: tuple[int, ...] = ()
    active_barriers: tuple[int, ...] = ()
    events: tuple[tuple[Event, float, float, float], ...] = ()
    saturation_joints: tuple[int, ...] = ()
    error: str = ""
    collision: CollisionRows | None = None
    active_pairs: tuple[int, ...] = ()
    dropped_events: int = 0

    def event(self, event: Event, status: StepStatus = StepStatus.OK, a: float = 0.0,
              b: float = 0.0, c: float = 0.0) -> None:
        """Record ``event`` and lower the status to ``status`` if it is worse."""
        if status.severity > self.status.severity:
            self.status = status
        self.events += ((event, a, b, c),)

    def fail(self, event: Event, error: str = "") -> None:
        """The step failed (its command is zero)."""
        self.status, self.error = StepStatus.FAILED, error
        self.events += ((event, 0.0, 0.0, 0.0),)


def code_mismatches(events: Mapping[str, int], statuses: Mapping[str, int],
                    methods: Mapping[str, int]) -> list[str]:
    """How the compiled step's codes (``controllers.cjm._step``'s ``EVENTS``, ``STATUSES``
    and ``METHODS``: name -> code, from ``_step/report.hpp``) differ from this module's:
    every C++ event is an :class:`Event` of the same name (upper case) and code, the
    statuses are :class:`~controllers.base.StepStatus`'s values by its order, the methods
    :data:`METHODS` by index (:data:`NO_METHOD` for ``""``). Empty when they agree."""
    mismatches = []
    for name, code in events.items():
        event = Event.__members__.get(name.upper())
        if event is None or event.value != code:
            python = "no such event" if event is None else f"{event.name} = {event.value}"
            mismatches.append(f"event {name} = {code} in C++, {python} in Python")
    for kind, compiled, python_codes in (
            ("status", statuses, {status.value: code for code, status in enumerate(StepStatus)}),
            ("method", methods, {method or NO_METHOD: code for code, method in enumerate(METHODS)})):
        if dict(compiled) != python_codes:
            mismatches.append(f"{kind} codes {dict(compiled)} in C++, {python_codes} in Python")
    return mismatches


def solve_info(report: StepReport, joint_names: Sequence[str]) -> SolveInfo:
    """The :class:`SolveInfo` of a step: its figures, and its events worded in order
    (:func:`report_message`; ``joint_names``: the joint's name per velocity index)."""
    collision = report.collision
    info = SolveInfo(report.status, report.method, report_message(report, joint_names),
                     report.sigma_min, report.damping, report.scale, report.saturated_joints,
                     report.active_barriers, report.equality_residual)
    if collision is not None:
        info.minimum_distance, info.closest_pair = collision.minimum_distance, collision.closest_pair
        info.active_pairs = tuple(collision.pairs[i] for i in report.active_pairs)
    return info


def report_message(report: StepReport, joint_names: Sequence[str]) -> str:
    """A step's message: its events worded in order, each note added once
    (:func:`~controllers.base.with_note`; a failure's or the hand-over's replaces the
    notes before it), then the collision pairs a step that misses its twist holds back by
    (none without an event; ``joint_names``: the joint's name per velocity index). The status is the report's:
    the words never change it."""
    events, collision, active_pairs = report.events, report.collision, report.active_pairs
    if not events:
        return ""
    message = ""
    for index, (event, a, b, c) in enumerate(events):  # the frequent events first
        if event is Event.TASK_RESIDUAL:
            # an active set solves again after each row it adds: the last solve's residual
            # is the command's (the earlier ones keep the status they lowered, never their
            # wording)
            if all(later[0] is not Event.TASK_RESIDUAL for later in events[index + 1:]):
                message = with_note(message, task_residual_note(a, b))
        elif event is Event.TASK_MISSED:
            message = with_note(message, task_missed_note(joint_names, report.saturation_joints,
                                                          a, b))
        elif event is Event.TASK_SCALED:
            message = with_note(message, task_scaled_note(joint_names, int(a), b))
        elif event is Event.CLIPPED:
            message = with_note(message, clipped_note(list(report.saturated_joints), a))
        elif event is Event.RESIDUAL:
            message = with_note(message, residual_note(a))
        elif event is Event.CONFLICT:
            message = with_note(message, conflict_note(int(a), int(b), c))
        elif event is Event.PAIR_CONFLICT:
            message = with_note(message, pair_conflict_note(collision.describe(int(a)), b))
        elif event is Event.ROWS_SCALED:
            message = with_note(message, rows_scaled_note(a))
        elif event is Event.NO_FREE_JOINT:
            message = with_note(message, NO_FREE_JOINT_NOTE)
        elif event is Event.PRE_CHAIN_SINGULAR:
            message = PRE_CHAIN_SINGULAR_NOTE  # the note replaces the message
        elif event is Event.PAPER_FORM_UNDEFINED:
            message = with_note(message, PAPER_FORM_NOTE)
        elif event is Event.NO_CONVERGENCE:
            message = NO_CONVERGENCE_NOTE
        elif event is Event.NON_FINITE:
            message = NON_FINITE_NOTE
        elif event is Event.LINEAR_ALGEBRA_ERROR:
            message = report.error
    if active_pairs and report.status in (StepStatus.LEAST_SQUARES, StepStatus.SCALED):
        message = with_note(message, held_back_note(collision, active_pairs))
    if report.dropped_events:
        message = with_note(message, dropped_events_note(report.dropped_events))
    return message


def dropped_events_note(count: int) -> str:
    """The events a step had no room to record (its message lacks their words)."""
    return f"{count} more event{'s' if count > 1 else ''} not recorded (the step's record is full)"


def pair_conflict_note(pair: str, shortfall: float) -> str:
    """A collision pair the equality rows leave no way to keep apart (section 18.4)."""
    return (f"collision pair {pair} cannot be kept apart with the constraints held: "
            f"least squares below them, distance rate {shortfall:.2e} m/s short")


def held_back_note(collision: CollisionRows, active_pairs: Sequence[int]) -> str:
    """The collision rows a step that misses its twist holds at their bound."""
    pairs = ", ".join(collision.describe(i) for i in active_pairs)
    return f"held back by collision pair{'s' if len(active_pairs) > 1 else ''} {pairs}"


def task_residual_note(damping: float, residual: float) -> str:
    """Why a DLS solution misses the task: damping near a singularity, or least squares."""
    note = (f"near a singularity: damped (lambda {damping:.2g})" if damping > 0
            else "task not fully achievable: least squares")
    return f"{note}, twist residual {residual:.2e}"


def conflict_note(rank: int, rows: int, residual: float) -> str:
    return (f"constraints conflict (rank {rank} < {rows} rows, "
            f"least-squares residual {residual:.2e} m/s)")


def rows_scaled_note(scale: float) -> str:
    """The note of a step whose rows' correction was scaled to fit the box."""
    return (f"the constraint's correction exceeds the joint limits: scaled to {scale:.0%}, "
            "the constraint converges as fast as they allow")


def task_missed_note(joint_names: Sequence[str], saturated: Sequence[int], sigma_min: float,
                     damping: float) -> str:
    """What keeps a saturated step from the task: the joints held at a limit, the
    damping near a singularity (eq 35), else a least-squares task (rank lost)."""
    limit = f"{joint_list(joint_names, saturated)} at a limit" if saturated else ""
    if saturated and not damping > 0.0:  # the common case: words only for the joints
        return f"{limit}: task not fully achievable"
    # below the rank cut sigma_min is rounding: 0 (the two backends round differently)
    sigma = f"sigma_min {sigma_min if sigma_min > RANK_TOLERANCE else 0.0:.2g}"
    if damping > 0.0:
        near = f"near a singularity ({sigma}, damping {damping:.2g})"
        return f"{limit}; {near}: task not fully achievable" if saturated else (
            f"{near}: task not fully achievable")
    return f"least squares ({sigma}): task not fully achievable"


def task_scaled_note(joint_names: Sequence[str], joint: int, scale: float) -> str:
    limit = f"{joint_list(joint_names, [joint])} at a limit" if joint >= 0 else "the joint limits"
    return f"{limit}: task scaled to {scale:.0%}"


def joint_list(joint_names: Sequence[str], velocity_indices: Sequence[int]) -> str:
    """``joint arm_joint_4`` / ``joints a, b`` for velocity indices (a multi-dof joint
    named once)."""
    if len(velocity_indices) == 1:
        return f"joint {joint_names[velocity_indices[0]]}"
    names = list(dict.fromkeys(joint_names[i] for i in velocity_indices))
    return f"joint{'s' if len(names) > 1 else ''} {', '.join(names)}"
