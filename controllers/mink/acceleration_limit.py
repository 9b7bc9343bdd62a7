"""Joint acceleration limits as a mink limit (docs/design.md section 8.4)."""

from __future__ import annotations

import mink
import numpy as np

from ..joint_acceleration import acceleration_box
from ..joint_limits import JointBounds
from ..mujoco_model import JointMap
from .joint_box import JointBoxLimit


class AccelerationLimit(JointBoxLimit):
    """``qd_prev - a dt <= qd <= qd_prev + a dt`` on mink's ``dq = v_mj dt``, as mink's
    ``VelocityLimit`` is ``|dq| <= v_max dt``; ``qd_prev`` is :attr:`reference`, the previous
    command (Pinocchio's velocity order; zero at rest).

    Where that box misses the joint box of position and velocity limits (a joint past a
    position limit, a plant that did not follow), it is the point of the joint box nearest
    to it (:func:`controllers.joint_acceleration.acceleration_box`): the acceleration gives
    way, so the two limits always have a common point. Only the box differs from
    :class:`controllers.mink.joint_box.JointBoxLimit`: the 1-dof joints' part is a bound on
    the variable and a planar base's part rows on its Pinocchio velocity ``P(th)^T v_mj``,
    as there.

    Parameters
    ----------
    bounds : the controller's joint box, with its acceleration limits.
    joints : the controller's ``JointMap``.
    nq : Pinocchio's configuration size.
    reference : the array holding the previous command (read at every step).
    change : with jerk limits, the array holding the previous command minus the one
        before (read at every step); the box is then the joint box cut by the acceleration
        and jerk limits (:meth:`JointBounds.box`, docs/design.md 8.5). None: none.
    """

    def __init__(self, bounds: JointBounds, joints: JointMap, nq: int,
                 reference: np.ndarray, change: np.ndarray | None = None) -> None:
        if bounds.acceleration_step is None:
            raise ValueError("AccelerationLimit needs a JointBounds with acceleration limits")
        super().__init__(bounds, joints, nq)
        self.reference = reference
        self.change = change

    def _box(self, configuration: mink.Configuration) -> tuple[np.ndarray, np.ndarray]:
        q = self.joints.q_to_pinocchio(configuration.q, out=self._q_pin)
        if self.change is not None:
            return self.bounds.box(q, self.reference, self.change)
        lower, upper = self.bounds.box(q)
        return acceleration_box(lower, upper, self.reference, self.bounds.acceleration_step)
