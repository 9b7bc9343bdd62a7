"""The project's joint box as a mink limit (docs/design.md sections 8 and 10.7)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import mink
import numpy as np
from mink.limits.limit import Constraint as LimitRows

from .joint_limits import JointBounds

if TYPE_CHECKING:
    from .mink_controller import JointMap


class JointBoxLimit(mink.Limit):
    """``lower <= qd <= upper`` of :meth:`JointBounds.box` as mink's ``G dq <= h``.

    The box is on Pinocchio's velocity ``v = M(q) v_mj`` (``M`` the joint map's column map:
    a permutation, and ``P(th)^T`` on a planar base's columns, ``mink_controller.PlanarBase``);
    mink's variable is ``dq = v_mj dt``, so the rows are::

        [ M; -M] dq <= [upper dt; -lower dt]        (rows with an infinite bound dropped)

    It replaces mink's ``ConfigurationLimit`` and ``VelocityLimit``, which have no common
    point once a joint is past a position limit by more than ``v_max dt / gain``; the box
    then asks the joint back, at most at its velocity limit, as every other controller's.

    Parameters
    ----------
    bounds : the controller's joint box (its ``dt`` must be the ``dt`` mink solves with).
    joints : the controller's ``JointMap`` (``q_to_pinocchio``, ``columns_to_mujoco``).
    nq : Pinocchio's configuration size.
    """

    def __init__(self, bounds: JointBounds, joints: JointMap, nq: int) -> None:
        self.bounds = bounds
        self.joints = joints
        self._q_pin = np.empty(nq)
        nv = len(bounds.velocity_limit)
        self._identity = np.eye(nv)

    def compute_qp_inequalities(
        self, configuration: mink.Configuration, dt: float
    ) -> LimitRows:
        """``G dq <= h`` at ``configuration`` (MuJoCo columns), ``h`` in ``dq`` units."""
        q_mj = configuration.q
        lower, upper = self.bounds.box(self.joints.q_to_pinocchio(q_mj, out=self._q_pin))
        to_pinocchio = self.joints.columns_to_mujoco(self._identity, q_mj)  # M: v = M v_mj
        has_upper, has_lower = np.isfinite(upper), np.isfinite(lower)
        if not (has_upper.any() or has_lower.any()):
            return LimitRows()
        G = np.vstack([to_pinocchio[has_upper], -to_pinocchio[has_lower]])
        h = np.concatenate([upper[has_upper], -lower[has_lower]]) * dt
        return LimitRows(G=G, h=h)
