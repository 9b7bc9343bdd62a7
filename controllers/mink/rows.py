"""Our constraint rows evaluated with Pinocchio at mink's configuration, cached per step."""

from __future__ import annotations

import mink
import numpy as np
import pinocchio as pin

from constraints import Constraint

from ..joint_acceleration import braked_lower
from ..mujoco_model import JointMap


class PinocchioRows:
    """Our constraint rows, evaluated with Pinocchio at a mink configuration.

    One Pinocchio kinematics pass per configuration, shared by all constraint tasks and
    barrier limits; each constraint's ``(A, b)`` (Pinocchio column order, ``A qd = b``,
    :meth:`constraints.Constraint.rows`) is then computed once and cached until the
    configuration changes.
    """

    def __init__(self, model: pin.Model, data: pin.Data, joints: JointMap,
                 mujoco_nq: int, acceleration_limit: np.ndarray | None = None,
                 dt: float = 0.0) -> None:
        self.model = model
        self.data = data
        self.joints = joints
        #: the acceleration limits (Pinocchio order; None: none) and the period the
        #: barriers' bounds brake with (docs/design.md 12)
        self.acceleration_limit, self.dt = acceleration_limit, dt
        self._q_mj = np.full(mujoco_nq, np.nan)
        self._q_pin = np.empty(model.nq)
        self.version = 0

    def mark_current(self, q_mj: np.ndarray) -> None:
        """Declare ``self.data`` up to date (joint Jacobians, frames) at ``q_mj``."""
        self._q_mj[:] = q_mj
        self.version += 1

    def ensure(self, configuration: mink.Configuration) -> None:
        """Bring ``self.data`` to ``configuration.q`` if it is not there already."""
        q_mj = configuration.q
        if (q_mj == self._q_mj).all():
            return
        self.joints.q_to_pinocchio(q_mj, out=self._q_pin)
        pin.computeJointJacobians(self.model, self.data, self._q_pin)
        pin.updateFramePlacements(self.model, self.data)
        self.mark_current(q_mj)


class RowsCache:
    """``(A_pin, A_mj, b)`` of one constraint, recomputed when the kinematics change; an
    inequality's ``b`` braking-aware with acceleration limits (docs/design.md 12)."""

    def __init__(self, constraint: Constraint, frame_id: int, rows: PinocchioRows) -> None:
        self.constraint = constraint
        self.frame_id = frame_id
        self.rows = rows
        self._version = -1
        self.A_pin = self.A_mj = self.b = np.zeros(0)

    def at(self, configuration: mink.Configuration) -> "RowsCache":
        rows = self.rows
        rows.ensure(configuration)
        if self._version != rows.version:
            constraint = self.constraint
            self.A_pin, self.b = constraint.rows(rows.model, rows.data, self.frame_id)
            if rows.acceleration_limit is not None and not constraint.is_equality:
                self.b = braked_lower(self.A_pin, self.b,
                                      constraint.error(rows.data.oMf[self.frame_id]),
                                      np.array([constraint.gain]), rows.acceleration_limit,
                                      rows.dt)
            self.A_mj = rows.joints.columns_to_mujoco(self.A_pin, configuration.q)
            self._version = rows.version
        return self

