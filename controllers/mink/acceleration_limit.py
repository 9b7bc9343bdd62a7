"""Joint acceleration limits as a mink limit (docs/design.md section 8.4)."""

from __future__ import annotations

import mink
import numpy as np
from mink.limits.limit import Constraint as LimitRows

from ..joint_acceleration import acceleration_box
from ..joint_limits import JointBounds
from ..mujoco_model import JointMap


class AccelerationLimit(mink.Limit):
    """``qd_prev - a dt <= qd <= qd_prev + a dt`` on mink's ``dq = v_mj dt``, as mink's
    ``VelocityLimit`` is ``|dq| <= v_max dt``; ``qd_prev`` is :attr:`reference`, the previous
    command (Pinocchio's velocity order; zero at rest).

    Where that box misses the joint box of position and velocity limits (a joint past a
    position limit, a plant that did not follow), it is the point of the joint box nearest
    to it (:func:`controllers.joint_acceleration.acceleration_box`): the acceleration gives
    way, so the two limits always have a common point. As
    :class:`controllers.mink.joint_box.JointBoxLimit`, the 1-dof joints' part is a bound on
    the variable (:meth:`displacement_bounds`) and a planar base's part the rows of
    :meth:`compute_qp_inequalities`, on its Pinocchio velocity ``P(th)^T v_mj``.

    Parameters
    ----------
    bounds : the controller's joint box, with its acceleration limits.
    joints : the controller's ``JointMap``.
    nq : Pinocchio's configuration size.
    reference : the array holding the previous command (read at every step).
    """

    def __init__(self, bounds: JointBounds, joints: JointMap, nq: int,
                 reference: np.ndarray) -> None:
        if bounds.acceleration_step is None:
            raise ValueError("AccelerationLimit needs a JointBounds with acceleration limits")
        self.bounds = bounds
        self.joints = joints
        self.reference = reference
        self._q_pin = np.empty(nq)
        self._nv = len(bounds.velocity_limit)

    def _box(self, configuration: mink.Configuration) -> tuple[np.ndarray, np.ndarray]:
        q = self.joints.q_to_pinocchio(configuration.q, out=self._q_pin)
        lower, upper = self.bounds.box(q)
        return acceleration_box(lower, upper, self.reference, self.bounds.acceleration_step)

    def displacement_bounds(self, configuration: mink.Configuration,
                            dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(lb, ub)`` on ``dq`` (MuJoCo dof order) for the 1-dof joints; ``-inf``/``inf``
        on a planar base's dofs."""
        lower, upper = self._box(configuration)
        lb, ub = np.full(self._nv, -np.inf), np.full(self._nv, np.inf)
        lb[self.joints.mj_v] = lower[self.joints.pin_v] * dt
        ub[self.joints.mj_v] = upper[self.joints.pin_v] * dt
        return lb, ub

    def compute_qp_inequalities(self, configuration: mink.Configuration,
                                dt: float) -> LimitRows:
        """A planar base's rows ``[P^T; -P^T] dq <= [upper; -lower] dt``; none without one."""
        base = self.joints.base
        if base is None:
            return LimitRows()
        lower, upper = self._box(configuration)
        speeds = slice(base.pin_v, base.pin_v + 3)
        lower, upper = lower[speeds], upper[speeds]
        to_pinocchio = np.zeros((3, self._nv))
        to_pinocchio[:, base.mj_v:base.mj_v + 3] = base.rotation(configuration.q).T
        has_upper, has_lower = np.isfinite(upper), np.isfinite(lower)
        if not (has_upper.any() or has_lower.any()):
            return LimitRows()
        return LimitRows(G=np.vstack([to_pinocchio[has_upper], -to_pinocchio[has_lower]]),
                         h=np.concatenate([upper[has_upper], -lower[has_lower]]) * dt)
