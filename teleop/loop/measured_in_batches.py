"""The measures of many periods of a run at once (docs/design.md 5.1 and section 7): what
:meth:`~teleop.loop.TeleopLoop.measure_later` computes period by period, in a few numpy
calls over all of them.

Per period only Pinocchio's kinematics are computed one by one (the joint Jacobians at the
sensed configuration, and at the true one before the period on a plant; the forward
kinematics at the end): the placements and ``LOCAL`` Jacobians of the frames the measures
read are stacked, then every measure is one stacked call over the periods whose geometry
has the same constraint types on the same frames: each constraint's evaluation by its
type's batched form (:mod:`teleop.loop.batched_evaluation`), its rows
``A = C (J_v - [p]x J_w)`` (section 3), ``A qd``, the residual, the drift ``-K e``, the
round-off floor (section 15.2), the EE velocities, the errors at the end. A stacked
``matmul`` multiplies each period's pair as the single product does, and what BLAS would
round by the CPU's kernel (the norms, ``R^T R*``) is element-wise, the same function for
one period and a stack (:mod:`constraints.norms`), so the numbers are those of the
period-by-period code bit for bit whatever BLAS kernel the CPU selects, but the floor's
world point ``R p + t`` (Pinocchio's ``act`` rounds it otherwise, within 1e-13 relative).
"""

from __future__ import annotations

import operator
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.norms import row_norms
from controllers.cjm.pose_rows import PERIOD_PLACEMENT, PERIOD_PREVIOUS, PERIOD_TARGET, PERIOD_TWIST

from .batched_evaluation import batched_form, times
from .constraint_measures import EPSILON, relative_rotations
from .measured_later import Geometry, MeasuredLater
from .records import StepRecord, step_record


#: what the measures read of each period and its step (C-level reads: once per period)
STEP, COMMAND, END, TRUE_Q, CONSTRAINTS = map(operator.attrgetter,
                                              ("step", "command", "end", "q", "constraints"))
SENSED, COMMANDED, MOVED, BEFORE, ROWS, HAS_PREVIOUS = map(
    operator.attrgetter, ("sensed", "qd", "moved", "q_before", "period_rows", "has_previous"))


@dataclass(frozen=True)
class Kinematics:
    """The model the measures read and what they read of it: the EE frames, the period
    ``dt`` (s) and whether a plant moved the joints (the velocities then at the true
    configuration before the period, with the joint velocities it applied)."""

    model: pin.Model
    data: pin.Data
    ee_frames: tuple[int, ...]
    dt: float
    plant: bool


def placements_and_jacobians(kinematics: Kinematics, configurations: Sequence[np.ndarray],
                             frames: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """At each configuration, each frame's world placement (N, F, 4, 4) and ``LOCAL``
    Jacobian (N, F, 6, nv), from ``computeJointJacobians``."""
    model, data = kinematics.model, kinematics.data
    placements: list[np.ndarray] = []
    jacobians: list[np.ndarray] = []
    jacobians_at, placement_of, jacobian_of = (pin.computeJointJacobians,
                                               pin.updateFramePlacement, pin.getFrameJacobian)
    for q in configurations:
        jacobians_at(model, data, q)
        for frame in frames:
            placements.append(placement_of(model, data, frame).homogeneous)
            jacobians.append(jacobian_of(model, data, frame, pin.LOCAL))
    count = len(configurations), len(frames)
    if not frames:
        return np.zeros((*count, 4, 4)), np.zeros((*count, 6, model.nv))
    return (np.concatenate(placements).reshape(*count, 4, 4),
            np.concatenate(jacobians).reshape(*count, 6, model.nv))


def placements_at(kinematics: Kinematics, configurations: Sequence[np.ndarray],
                  frames: Sequence[int]) -> np.ndarray:
    """At each configuration, each frame's world placement (N, F, 4, 4), from
    ``forwardKinematics``."""
    model, data = kinematics.model, kinematics.data
    placements: list[np.ndarray] = []
    kinematics_at, placement_of = pin.forwardKinematics, pin.updateFramePlacement
    for q in configurations:
        kinematics_at(model, data, q)
        for frame in frames:
            placements.append(placement_of(model, data, frame).homogeneous)
    return np.concatenate(placements).reshape(len(configurations), len(frames), 4, 4)


def column_major(matrices: np.ndarray) -> np.ndarray:
    """``matrices`` (..., 3, 3) each stored column-major, as ``pin.SE3.rotation`` returns
    them (BLAS multiplies such a matrix by a vector in another order: the same bits need
    the same layout)."""
    return np.ascontiguousarray(matrices.swapaxes(-1, -2)).swapaxes(-1, -2)


def skew(vectors: np.ndarray) -> np.ndarray:
    """``[p]x`` of each row of ``vectors`` (N, 3) -> (N, 3, 3), as ``pin.skew``."""
    x, y, z = vectors.T
    zero = np.zeros_like(x)
    return np.stack([zero, -z, y, z, zero, -x, -y, x, zero], axis=1).reshape(-1, 3, 3)


@dataclass(frozen=True)
class RowMeasures:
    """The command's measures at ``N`` periods (:func:`constraint_velocity`'s, stacked):
    ``max |A qd - b|`` (N,), each equality row's ``C v_c - C v_geom`` (N, rows), its drift
    ``-K e`` (N, rows) and the round-off floor (N,)."""

    residual: np.ndarray
    velocity: np.ndarray
    drift: np.ndarray
    floor: np.ndarray


def constraint_velocity(geometries: Sequence[Geometry], placements: np.ndarray,
                        jacobians: np.ndarray, velocities: np.ndarray) -> RowMeasures:
    """:func:`teleop.loop.constraint_measures.constraint_velocity` at every period, its
    equality constraints' placements and Jacobians first in ``placements`` and
    ``jacobians`` (in their order), ``velocities`` (N, nv) the joints'."""
    count = len(geometries)
    residual, floor = np.zeros(count), np.zeros(count)
    velocity, drift = [np.zeros((count, 0))], [np.zeros((count, 0))]
    speeds = np.abs(velocities)
    equalities = [j for j, constraint in enumerate(geometries[0].constraints)
                  if constraint.is_equality]
    for slot, j in enumerate(equalities):
        constraints: list[Constraint] = list(map(operator.itemgetter(j), map(CONSTRAINTS, geometries)))
        rotations, translations = placements[:, slot, :3, :3], placements[:, slot, :3, 3]
        point = batched_form(type(constraints[0])).evaluate(constraints, rotations,
                                                            translations)
        jacobian = jacobians[:, slot]
        A = np.matmul(point.C, jacobian[:, :3] - np.matmul(skew(point.p), jacobian[:, 3:]))
        achieved = times(A, velocities)
        residual = np.maximum(residual, np.abs(achieved - point.rhs).max(axis=1))
        gains = np.array([constraint.gain for constraint in constraints])
        correction = -gains[:, None] * point.error
        velocity.append(achieved - (point.rhs - correction))
        drift.append(correction)
        world = times(rotations, point.p) + translations
        floor = np.maximum(floor, times(np.abs(A), speeds).max(axis=1)
                           + gains * row_norms(world))
    return RowMeasures(residual, np.concatenate(velocity, axis=1),
                       np.concatenate(drift, axis=1), floor * EPSILON)


def runs(geometries: Sequence[Geometry]) -> list[slice]:
    """The runs of consecutive periods whose geometry is one constraint set on the same
    frames (the same labels and names), each a slice of ``geometries``."""
    starts = [0] + [i for i in range(1, len(geometries))
                    if geometries[i].labels is not geometries[i - 1].labels
                    or geometries[i].names is not geometries[i - 1].names
                    or geometries[i].frames is not geometries[i - 1].frames]
    return [slice(start, end) for start, end in zip(starts, starts[1:] + [len(geometries)])]


def equality_frames(geometry: Geometry) -> list[int]:
    """The frames of ``geometry``'s equality constraints, in their order."""
    return [frame for constraint, frame in zip(geometry.constraints, geometry.frames)
            if constraint.is_equality]


@dataclass(frozen=True)
class CommandMeasures:
    """:meth:`TeleopLoop.measure_command`'s measures of ``N`` periods: the rows'
    (:class:`RowMeasures`) and the EE velocities (N, EEs, 3), world frame."""

    rows: RowMeasures
    actual: np.ndarray


def measure_commands(kinematics: Kinematics, periods: Sequence[MeasuredLater],
                     ) -> CommandMeasures:
    """The command's measures of ``periods`` (one constraint set on the same frames):
    the rows at the sensed configuration with the command; with a plant, but the
    residual, again at the true configuration before the period with the joint
    velocities the plant applied; the EE velocities where the rows are last measured."""
    geometries = list(map(COMMAND, periods))
    steps = list(map(STEP, periods))
    frames = equality_frames(geometries[0])
    ees = list(kinematics.ee_frames)
    sensed = list(map(SENSED, steps))
    commands = np.array(list(map(COMMANDED, steps)))
    placements, jacobians = placements_and_jacobians(
        kinematics, sensed, frames if kinematics.plant else frames + ees)
    rows = constraint_velocity(geometries, placements, jacobians, commands)
    moved = commands
    if kinematics.plant:
        moved = np.array(list(map(MOVED, steps)))
        placements, jacobians = placements_and_jacobians(
            kinematics, list(map(BEFORE, steps)), frames + ees)
        at_true = constraint_velocity(geometries, placements, jacobians, moved)
        rows = RowMeasures(rows.residual, at_true.velocity, at_true.drift, at_true.floor)
    ee_rotations = column_major(placements[:, len(frames):, :3, :3])
    ee_linear = np.matmul(jacobians[:, len(frames):, :3], moved[:, None, :, None])[..., 0]
    return CommandMeasures(rows, times(ee_rotations, ee_linear))


@dataclass(frozen=True)
class EndMeasures:
    """:meth:`TeleopLoop.measure`'s errors of ``N`` periods at the end: each constraint's
    violation (N, constraints), the largest equality error and barrier penetration (N,),
    each EE's position and orientation error (N, EEs)."""

    violations: np.ndarray
    error: np.ndarray
    penetration: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray


def measure_ends(kinematics: Kinematics, periods: Sequence[MeasuredLater],
                 targets: np.ndarray) -> EndMeasures:
    """The end-of-period errors of ``periods`` (one constraint set on the same frames) at
    their true configurations, against each EE's filtered target (the period rows'
    targets, ``targets`` (N, EEs, 12))."""
    geometries = list(map(END, periods))
    count, ees = len(periods), len(kinematics.ee_frames)
    placements = placements_at(kinematics, list(map(TRUE_Q, periods)),
                               list(kinematics.ee_frames) + list(geometries[0].frames))
    error, penetration = np.zeros(count), np.zeros(count)
    violations = [np.zeros((count, 0))]
    for j, constraint in enumerate(geometries[0].constraints):
        constraints = list(map(operator.itemgetter(j), map(CONSTRAINTS, geometries)))
        kind: type[Constraint] = type(constraint)
        violation = batched_form(kind).violation(
            constraints, placements[:, ees + j, :3, :3], placements[:, ees + j, :3, 3])
        violations.append(violation[:, None])
        if constraint.is_equality:
            error = np.maximum(error, violation)
        else:
            penetration = np.maximum(penetration, violation)
    offsets = placements[:, :ees, :3, 3] - targets[..., 9:12]
    rotations = relative_rotations(placements[:, :ees, :3, :3],
                                   targets[..., :9].reshape(count, ees, 3, 3))
    logs = np.array([pin.log3(rotation) for rotation in rotations.reshape(-1, 3, 3)])
    return EndMeasures(np.concatenate(violations, axis=1), error, penetration,
                       row_norms(offsets), row_norms(logs).reshape(count, ees))


def measure_periods(kinematics: Kinematics, periods: Sequence[MeasuredLater],
                    ) -> list[StepRecord]:
    """The records of ``periods`` (none measured yet), as :meth:`TeleopLoop.measure_later`
    computes them one by one."""
    if not periods:
        return []
    model = kinematics.model
    steps = list(map(STEP, periods))
    rows = np.array(list(map(ROWS, steps)))
    count = len(periods)
    commanded = times(column_major(rows[..., PERIOD_PLACEMENT][..., :9].reshape(count, -1, 3, 3)),
                      rows[..., PERIOD_TWIST][..., :3])
    previous = np.array(list(map(HAS_PREVIOUS, steps)))
    operator = np.where(previous[:, None, None],
                        (rows[..., PERIOD_TARGET][..., 9:12]
                         - rows[..., PERIOD_PREVIOUS][..., 9:12]) / kinematics.dt, 0.0)
    residual, floor = np.empty(count), np.empty(count)
    velocity: list[np.ndarray] = [np.zeros(0)] * count
    drift: list[np.ndarray] = [np.zeros(0)] * count
    actual = np.empty_like(commanded)
    for run in runs(list(map(COMMAND, periods))):
        measured = measure_commands(kinematics, periods[run])
        residual[run], floor[run] = measured.rows.residual, measured.rows.floor
        velocity[run], drift[run] = list(measured.rows.velocity), list(measured.rows.drift)
        actual[run] = measured.actual
    ends: list[EndMeasures] = []
    for run in runs(list(map(END, periods))):
        ends.append(measure_ends(kinematics, periods[run], rows[run][..., PERIOD_TARGET]))
    error = np.concatenate([end.error for end in ends])
    penetration = np.concatenate([end.penetration for end in ends])
    positions = np.concatenate([end.positions for end in ends])
    orientations = np.concatenate([end.orientations for end in ends])
    violations = [row for end in ends for row in end.violations]
    q = np.array(list(map(TRUE_Q, periods)))
    limits = np.maximum(0.0, np.maximum((q - model.upperPositionLimit).max(axis=1),
                                        (model.lowerPositionLimit - q).max(axis=1)))
    records = []
    for (period, error_i, residual_i, penetration_i, positions_i, orientations_i, limit_i,
         floor_i, velocity_i, drift_i, operator_i, commanded_i, actual_i, violations_i) in zip(
            periods, error.tolist(), residual.tolist(), penetration.tolist(), list(positions),
            list(orientations), limits.tolist(), floor.tolist(), velocity, drift,
            list(operator), list(commanded), list(actual), violations):
        step = period.step  # the command's measures, into it (as TeleopLoop.measure_command)
        step.residual, step.floor, step.labels = residual_i, floor_i, period.command.labels
        step.constraint_velocity, step.drift_velocity = velocity_i, drift_i
        step.operator_linear_velocities = operator_i
        step.commanded_linear_velocities, step.actual_linear_velocities = commanded_i, actual_i
        records.append(step_record(step, period.t, error_i, penetration_i, positions_i,
                                   orientations_i, limit_i, violations_i, period.end.names,
                                   period.plant))
    return records
