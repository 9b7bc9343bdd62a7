"""The project's joint box as a mink limit (docs/design.md sections 8 and 10.7)."""

from __future__ import annotations

import mink
import numpy as np
from mink.limits.limit import Constraint as LimitRows

from ..joint_limits import JointBounds
from ..mujoco_model import JointMap


class JointBoxLimit(mink.Limit):
    """``lower <= qd <= upper`` of :meth:`JointBounds.box` on mink's ``dq = v_mj dt``.

    It replaces mink's ``ConfigurationLimit`` and ``VelocityLimit``, which have no common
    point once a joint is past a position limit by more than ``v_max dt / gain``; the box
    then asks the joint back, at most at its velocity limit, as every other controller's.

    The box is on Pinocchio's velocity ``v``. A 1-dof joint's MuJoCo dof is its Pinocchio
    one (``JointMap``), so its part is a bound on the variable
    (:meth:`displacement_bounds`, ``lower dt <= dq <= upper dt``): past a limit the box
    pins the joint (``lower = upper``), which a backend takes as a fixed variable, whereas
    the two opposite rows ``dq <= u dt``, ``-dq <= -u dt`` of an inequality make an active
    set that is linearly dependent (daqp at mink's tolerance then finds no solution). A
    planar base's velocity is ``P(th)^T`` times MuJoCo's
    (:class:`controllers.mujoco_model.PlanarBase`); it has no position limit, so its part is
    the rows of :meth:`compute_qp_inequalities`.

    Parameters
    ----------
    bounds : the controller's joint box (its ``dt`` must be the ``dt`` mink solves with).
    joints : the controller's ``JointMap``.
    nq : Pinocchio's configuration size.
    """

    def __init__(self, bounds: JointBounds, joints: JointMap, nq: int) -> None:
        self.bounds = bounds
        self.joints = joints
        self._q_pin = np.empty(nq)
        self._nv = len(bounds.velocity_limit)

    def _box(self, configuration: mink.Configuration) -> tuple[np.ndarray, np.ndarray]:
        return self.bounds.box(self.joints.q_to_pinocchio(configuration.q, out=self._q_pin))

    def displacement_bounds(self, configuration: mink.Configuration,
                            dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``(lb, ub)`` on ``dq`` (MuJoCo dof order): ``lower dt``, ``upper dt`` on the 1-dof
        joints, ``-inf``/``inf`` on a planar base's dofs."""
        lower, upper = self._box(configuration)
        lb, ub = np.full(self._nv, -np.inf), np.full(self._nv, np.inf)
        lb[self.joints.mj_v] = lower[self.joints.pin_v] * dt
        ub[self.joints.mj_v] = upper[self.joints.pin_v] * dt
        return lb, ub

    def compute_qp_inequalities(
        self, configuration: mink.Configuration, dt: float
    ) -> LimitRows:
        """A planar base's rows ``[P^T; -P^T] dq <= [upper; -lower] dt`` (its base columns,
        rows with an infinite bound dropped); none without a base."""
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
