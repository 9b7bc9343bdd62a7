"""What a period records (docs/design.md sections 5.1 and 7): the hot path's
:class:`PendingStep` (a :class:`CompiledPendingStep` when the compiled tick ran it), then
the measured :class:`StepRecord`."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from controllers.cjm.pose_rows import (PERIOD_PLACEMENT, PERIOD_PREVIOUS, PERIOD_TARGET,
                                       PERIOD_TWIST, pose_rows, row_pose, row_views)
from controllers.step_message import NO_MESSAGE, StepMessage

from .supervisor import Supervision

#: Columns of the per-step record, in order (see :class:`StepRecord`).
RECORD_FIELDS = (
    "t", "constraint_error", "constraint_velocity_residual", "barrier_penetration",
    "ee_position_error", "ee_orientation_error", "joint_limit_violation", "failed",
    "step_time_us", "tick_time_us", "constraint_velocity_floor", "twist_saturated",
    "minimum_distance", "measured_constraint_error", "measured_port_force", "supervisor_scale",
    "supervisor_target_offset", "supervisor_target_offset_angle",
)


@dataclass
class StepRecord:
    """What one tick measured. Errors in m / rad, velocities in m/s, times in us.

    The velocities are those the robot moves with over the period, at its true
    configuration (docs/design.md section 15.2): every equality row's ``C v_c`` relative to
    the constraint's moving geometry, and each EE's linear velocity, world frame. Beside the
    achieved EE velocity: the operator's (filtered) target velocity and the commanded twist's
    linear part, which also carries the pose-error term and the speed caps.

    Per end effector (``robot.ee_frames`` order): ``ee_position_errors``,
    ``ee_orientation_errors`` and the ``*_linear_velocities`` rows. The single-EE names
    read them: ``ee_position_error`` and ``ee_orientation_error`` are the worst EE's, the
    ``*_linear_velocity`` vectors the first EE's (``robot.ee_frame``); with one EE both are
    that EE's, as they always were.
    """

    t: float
    constraint_error: float  # max over equality constraints of |e|
    constraint_velocity_residual: float  # max |C v_c - (-K e + ff)| over equalities
    barrier_penetration: float  # max depth behind a barrier (0 on the allowed side)
    ee_position_errors: np.ndarray  # (EEs,) |p_e - p*| of each EE against its filtered target
    ee_orientation_errors: np.ndarray  # (EEs,) |log3(R_e^T R*)| of each EE
    joint_limit_violation: float  # max over joints of the distance past a limit (rad)
    failed: bool
    step_time_us: float  # the controller's solve (the compiled tick: its C++ step alone)
    tick_time_us: float  # the period's hot path, the solve included (the measures are not)
    constraint_velocity_floor: float  # float64 round-off of C v_c (m/s, constraint_measures)
    twist_saturated: bool  # the speed caps scaled some EE's commanded twist down
    constraint_velocity: np.ndarray = field(repr=False)  # C v_c - C v_geom, every equality row
    constraint_velocity_labels: tuple[str, ...] = field(repr=False)  # one per row (row_labels)
    drift_velocity: np.ndarray = field(repr=False)  # -K e per row at the true configuration
    operator_linear_velocities: np.ndarray = field(repr=False)  # (EEs, 3) the filtered targets'
    commanded_linear_velocities: np.ndarray = field(repr=False)  # (EEs, 3) of the commanded twists
    actual_linear_velocities: np.ndarray = field(repr=False)  # (EEs, 3) world frame
    constraint_errors: np.ndarray = field(repr=False)  # each constraint's violation (m)
    constraint_names: tuple[str, ...] = field(repr=False)  # one per constraint (constraint_names)
    #: the loop's status: the controller's, or ``constraint_degraded`` when a measure at
    #: the sensed configuration is beyond the supervisor's tolerance (docs/design.md 5.2)
    status: str = "ok"
    #: why the status is not ``ok``, worded when read (:attr:`message`)
    step_message: StepMessage = NO_MESSAGE
    controller_status: str = "ok"  # the controller's own step status (controllers.StepStatus)
    #: the largest constraint error measured at the sensed configuration (m)
    measured_constraint_error: float = 0.0
    measured_port_force: float = math.nan  # the largest port force measured (N), NaN: none
    supervisor_scale: float = 1.0  # what the supervisor multiplied the operator's motion by
    supervisor_action: str = "none"  # teleop.loop.supervisor.ACTIONS
    #: the largest distance between an EE's supervised target and the operator's (m)
    supervisor_target_offset: float = 0.0
    supervisor_target_offset_angle: float = 0.0  # the largest angle between them (rad)
    plant: object | None = field(default=None, repr=False)  # the plant's own measures
    #: the collision pairs' smallest distance at the true configuration (m; inf without
    #: collision avoidance or no pair measured; exact below d_i, teleop.loop.distance_meter)
    minimum_distance: float = math.inf
    closest_pair: str = ""  # the pair of minimum_distance ("first | second"), "" when none

    @property
    def message(self) -> str:
        """The loop's message in words (the controller's, and the supervisor's)."""
        return self.step_message.text

    @property
    def ee_position_error(self) -> float:
        """The worst EE's position error (m)."""
        return float(np.max(self.ee_position_errors))

    @property
    def ee_orientation_error(self) -> float:
        """The worst EE's orientation error (rad)."""
        return float(np.max(self.ee_orientation_errors))

    @property
    def operator_linear_velocity(self) -> np.ndarray:
        """The first EE's filtered target velocity (world, m/s)."""
        return self.operator_linear_velocities[0]

    @property
    def commanded_linear_velocity(self) -> np.ndarray:
        """The first EE's commanded linear velocity (world, m/s)."""
        return self.commanded_linear_velocities[0]

    @property
    def actual_linear_velocity(self) -> np.ndarray:
        """The first EE's achieved linear velocity (world, m/s)."""
        return self.actual_linear_velocities[0]


def step_record(step: PendingStep, t: float, constraint_error: float,
                barrier_penetration: float, ee_position_errors: np.ndarray,
                ee_orientation_errors: np.ndarray, joint_limit_violation: float,
                constraint_errors: np.ndarray, constraint_names: tuple[str, ...],
                plant: object | None, minimum_distance: float = math.inf,
                closest_pair: str = "") -> StepRecord:
    """The record of ``step``, a supervised period with its command's measures in it
    (:meth:`TeleopLoop.measure_command`, or the batch's), at time ``t`` with the measures
    at the end of the period (:class:`StepRecord`'s fields of the same names; ``plant``:
    the plant's own measures). The one place a record is made of a step."""
    supervision = step.supervision
    assert supervision is not None  # every period the loop ran was supervised
    return StepRecord(
        t=t, constraint_error=constraint_error,
        constraint_velocity_residual=step.residual, barrier_penetration=barrier_penetration,
        ee_position_errors=ee_position_errors, ee_orientation_errors=ee_orientation_errors,
        joint_limit_violation=joint_limit_violation, failed=step.status == "failed",
        step_time_us=step.step_time_us, tick_time_us=step.tick_time_us,
        constraint_velocity_floor=step.floor, twist_saturated=step.twist_saturated,
        constraint_velocity=step.constraint_velocity, constraint_velocity_labels=step.labels,
        drift_velocity=step.drift_velocity,
        operator_linear_velocities=step.operator_linear_velocities,
        commanded_linear_velocities=step.commanded_linear_velocities,
        actual_linear_velocities=step.actual_linear_velocities,
        constraint_errors=constraint_errors, constraint_names=constraint_names,
        status=step.status, step_message=step.step_message,
        controller_status=step.controller_status,
        measured_constraint_error=supervision.error, measured_port_force=supervision.port_force,
        supervisor_scale=supervision.scale, supervisor_action=supervision.action,
        supervisor_target_offset=supervision.target_offset,
        supervisor_target_offset_angle=supervision.target_offset_angle, plant=plant,
        minimum_distance=minimum_distance, closest_pair=closest_pair)


@dataclass
class PendingStep:
    """One period as :meth:`TeleopLoop.advance` ran it (the hot path), then its command's
    measures (:meth:`TeleopLoop.measure_command`), waiting for the end-of-period ones."""

    targets: list[pin.SE3]  # the filtered target of each EE
    previous_targets: list[pin.SE3] | None  # the period before's (the operator's velocity)
    placements: list[pin.SE3]  # each EE's pose the command was computed from
    twists: list[np.ndarray]  # each EE's commanded body twist, after the speed caps
    sensed: np.ndarray  # the configuration the controller saw
    q_before: np.ndarray  # the true configuration before the integration
    qd: np.ndarray  # the command
    moved: np.ndarray  # the joint velocities the robot moved with (the plant's)
    tick_time_us: float  # the hot path: filter, kinematics, command, solve, integration
    step_time_us: float
    status: str  # the controller's, then the loop's (:meth:`supervised_by`)
    step_message: StepMessage  # its message, worded when read (:attr:`message`)
    twist_saturated: bool
    controller_status: str = "ok"
    supervision: Supervision | None = None  # what the supervisor measured and did
    residual: float = 0.0
    floor: float = 0.0
    constraint_velocity: np.ndarray = field(default_factory=lambda: np.zeros(0))
    drift_velocity: np.ndarray = field(default_factory=lambda: np.zeros(0))
    labels: tuple[str, ...] = ()
    operator_linear_velocities: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    commanded_linear_velocities: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    actual_linear_velocities: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def message(self) -> str:
        """The status's message in words."""
        return self.step_message.text

    def supervised_by(self, supervision: Supervision) -> PendingStep:
        """This step with the loop's status (:meth:`Supervision.status_of`); the
        controller's kept in ``controller_status``."""
        self.controller_status, self.supervision = self.status, supervision
        self.status, self.step_message = supervision.status_of(self.status, self.step_message)
        return self

    @property
    def target_translations(self) -> list[np.ndarray]:
        """Each EE's filtered target position (world)."""
        return [target.translation for target in self.targets]

    @property
    def previous_translations(self) -> list[np.ndarray] | None:
        """Each EE's filtered target position of the period before, None at the start."""
        previous = self.previous_targets
        return None if previous is None else [target.translation for target in previous]

    @property
    def target_rotations(self) -> list[np.ndarray]:
        """Each EE's filtered target orientation (world, 3 x 3)."""
        return [target.rotation for target in self.targets]

    @property
    def has_previous(self) -> bool:
        """Whether the period before's targets are known (not the first period)."""
        return self.previous_targets is not None

    @property
    def period_rows(self) -> np.ndarray:
        """The period as the compiled tick keeps it (:mod:`controllers.cjm.pose_rows`),
        one row per EE: the filtered target, the previous one (zeros at the start), the
        EE placement, each a pose row, then the commanded twist."""
        count = len(self.targets)
        return np.hstack([pose_rows(self.targets, count),
                          pose_rows(self.previous_targets, count),
                          pose_rows(self.placements, count), np.array(self.twists)])


#: the measures' defaults of a compiled period (replaced, never written in place)
NO_ROWS = np.zeros(0)
NO_ROWS.flags.writeable = False
NO_VECTORS = np.zeros((0, 3))
NO_VECTORS.flags.writeable = False


class CompiledPendingStep(PendingStep):
    """A period the compiled tick ran (docs/design.md 5.1). Its poses and twists are in
    ``period``, the tick's copy (per EE: the filtered target, the previous target, the
    EE placement and the commanded twist, :mod:`controllers.cjm.pose_rows`); they become ``pin.SE3`` objects
    and arrays only when a measure reads them, so the periods nobody measures build
    none. The measures' fields start empty, as :class:`PendingStep`'s."""

    constraint_velocity = drift_velocity = NO_ROWS
    operator_linear_velocities = commanded_linear_velocities = NO_VECTORS
    actual_linear_velocities = NO_VECTORS

    def __init__(self, period: np.ndarray, has_previous: bool, sensed: np.ndarray,
                 q_before: np.ndarray, qd: np.ndarray, moved: np.ndarray, tick_time_us: float,
                 step_time_us: float, status: str, step_message: StepMessage,
                 twist_saturated: bool) -> None:
        self.period, self._has_previous = period, has_previous
        self.sensed, self.q_before, self.qd, self.moved = sensed, q_before, qd, moved
        self.tick_time_us, self.step_time_us = tick_time_us, step_time_us
        self.status, self.step_message = status, step_message
        self.twist_saturated = twist_saturated

    @property
    def has_previous(self) -> bool:
        return self._has_previous

    @property
    def period_rows(self) -> np.ndarray:
        return self.period

    @functools.cached_property
    def targets(self) -> list[pin.SE3]:
        return [row_pose(row[PERIOD_TARGET]) for row in self.period]

    @functools.cached_property
    def previous_targets(self) -> list[pin.SE3] | None:
        return [row_pose(row[PERIOD_PREVIOUS]) for row in self.period] if self.has_previous else None

    @functools.cached_property
    def placements(self) -> list[pin.SE3]:
        return [row_pose(row[PERIOD_PLACEMENT]) for row in self.period]

    @functools.cached_property
    def twists(self) -> list[np.ndarray]:
        return list(self.period[:, PERIOD_TWIST])

    # the poses' parts the measures read, from the rows: no pin.SE3 built for them

    @property
    def target_translations(self) -> list[np.ndarray]:
        return [row_views(row[PERIOD_TARGET])[1] for row in self.period]

    @property
    def previous_translations(self) -> list[np.ndarray] | None:
        return ([row_views(row[PERIOD_PREVIOUS])[1] for row in self.period]
                if self.has_previous else None)

    @property
    def target_rotations(self) -> list[np.ndarray]:
        return [row_views(row[PERIOD_TARGET])[0] for row in self.period]
