"""The loop's measures of the constraints (docs/design.md section 7 and 15.2), functions of
the kinematics a caller computed: the command's constraint velocities and residual, the
errors after integration. :class:`~teleop.loop.TeleopLoop` takes them in
:meth:`~teleop.loop.TeleopLoop.measure_command` and :meth:`~teleop.loop.TeleopLoop.measure`."""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.base import evaluated_rows
from constraints.norms import norm

#: float64's machine epsilon (the round-off floor's unit, :func:`constraint_velocity`)
EPSILON = float(np.finfo(float).eps)


def relative_rotations(rotations: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """``R_i^T R*_i`` of each pair of rotation matrices (..., 3, 3), entry ``(a, b)``
    ``(R_0a R*_0b + R_1a R*_1b) + R_2a R*_2b`` in element-wise operations: the same bits for
    one pair as for a stack, whatever BLAS kernel the CPU selects (:mod:`constraints.norms`)."""
    return (rotations[..., 0, :, None] * targets[..., 0, None, :]
            + rotations[..., 1, :, None] * targets[..., 1, None, :]
            + rotations[..., 2, :, None] * targets[..., 2, None, :])


def constraint_velocity(qd: np.ndarray, model: pin.Model, data: pin.Data,
                        constraints: Sequence[Constraint], frames: Sequence[int],
                        ) -> tuple[float, np.ndarray, np.ndarray, float]:
    """At the kinematics in ``data``: ``max |A qd - b|`` over the equalities, every
    equality row's ``C v_c - C v_geom`` (the point's velocity relative to its moving
    geometry), its drift correction ``-K e``, and the round-off floor of those
    velocities, ``eps max (sum_j |A_ij qd_j| + K |x|)`` with ``x`` the point's world
    position, from which ``e`` is computed (m/s; docs/design.md section 15.2)."""
    residual, floor = 0.0, 0.0
    velocity, drift = [], []
    speeds = np.abs(qd)
    for constraint, frame in zip(constraints, frames):
        if not constraint.is_equality:
            continue
        A, state, placement = evaluated_rows(constraint, model, data, frame)
        achieved = A @ qd
        residual = max(residual, *map(abs, (achieved - state.rhs).tolist()))
        correction = -constraint.gain * state.error
        velocity.append(achieved - (state.rhs - correction))
        drift.append(correction)
        point = placement.act(state.p)
        floor = max(floor, max((np.abs(A) @ speeds).tolist())
                    + constraint.gain * norm(point))
    if not velocity:
        return 0.0, np.zeros(0), np.zeros(0), 0.0
    return (residual, np.concatenate(velocity), np.concatenate(drift),
            floor * EPSILON)

def constraint_errors(model: pin.Model, data: pin.Data,
                       constraints: Sequence[Constraint], frames: Sequence[int],
                       ) -> tuple[np.ndarray, float, float]:
    """After integration, at the true configuration on ``model`` (its joints' placements
    in ``data``), ``constraints`` on ``frames``: each constraint's own ``violation``,
    then the max |e| over equalities and the max inequality (barrier) penetration."""
    error, penetration = 0.0, 0.0
    violations = []
    for constraint, frame in zip(constraints, frames):
        violation = constraint.violation(pin.updateFramePlacement(model, data, frame))
        violations.append(violation)
        if constraint.is_equality:
            error = max(error, violation)
        else:
            penetration = max(penetration, violation)
    return np.array(violations), error, penetration
