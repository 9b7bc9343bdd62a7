"""The project's rows, posture and damping as mink tasks and limits (docs/design.md 4.8).

mink holds a task in ``constraints=`` as the hard row ``J dq = -gain e`` and a limit as
``G dq <= h``, both on the displacement ``dq = v dt`` (MuJoCo dof order).
"""

from __future__ import annotations

from collections.abc import Callable

import mink
import numpy as np
import pinocchio as pin
from mink.limits.limit import Constraint as LimitRows

from constraints import Constraint

from ..mujoco_model import JointMap
from .rows import RowsCache


class ConstraintTask(mink.Task):
    """An equality constraint ``A qd = b`` as a mink task, to pass in ``constraints=``.

    mink holds a task in ``constraints=`` as the hard row ``J dq = -gain e`` on the
    displacement ``dq = v dt``. With::

        J = A,   e = -b dt,   gain = 1

    that row is ``A v dt = b dt``, i.e. exactly ``A v = b`` in rad/s: the same rows, drift
    feedback ``-K e_c`` and feed-forward as the CJM and QP controllers. (``e`` is the
    *displacement* the row asks for in one step, with the sign mink expects; as a soft
    task it would cost ``|A dq - b dt|^2``.)
    """

    def __init__(self, cache: RowsCache, dt: float) -> None:
        super().__init__(cost=np.ones(cache.constraint.dim), gain=1.0, lm_damping=0.0)
        self.cache = cache
        self.dt = float(dt)
        #: the right-hand side held instead of ``b`` (the least-residual stage), or None
        self.held_rhs: np.ndarray | None = None

    @property
    def constraint(self) -> Constraint:
        return self.cache.constraint

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        """``e = -b dt`` (k,), so that ``J dq = -e`` reads ``A v = b`` (``held_rhs``
        instead of ``b`` when set)."""
        rows = self.cache.at(configuration)
        return -self.dt * (rows.b if self.held_rhs is None else self.held_rhs)

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        """``J = A`` (k x nv), columns in MuJoCo dof order."""
        return self.cache.at(configuration).A_mj


class BarrierLimit(mink.Limit):
    """A barrier ``A qd >= b`` (``n . v_c >= -K d + n . v_plane``) as a mink limit.

    mink limits are ``G dq <= h`` on ``dq = v dt``, so the row is
    ``G = -A``, ``h = -b dt`` (``A v >= b``, scaled by ``dt > 0``): the QP controller's
    ``G qd <= h`` row, in mink's units.
    """

    def __init__(self, cache: RowsCache) -> None:
        self.cache = cache
        #: the bound held instead of ``b`` (the least-residual stage), or None
        self.held_rhs: np.ndarray | None = None

    @property
    def constraint(self) -> Constraint:
        return self.cache.constraint

    def compute_qp_inequalities(
        self, configuration: mink.Configuration, dt: float
    ) -> LimitRows:
        """``G dq <= h`` with ``G = -A`` (MuJoCo columns) and ``h = -b dt``."""
        rows = self.cache.at(configuration)
        return LimitRows(G=-rows.A_mj, h=-dt * (rows.b if self.held_rhs is None
                                                else self.held_rhs))


class PostureTask(mink.Task):
    """mink's posture task with the CJM's posture velocity, in MuJoCo coordinates.

    ``mink.PostureTask`` has ``e = q (-) q_posture`` (``mj_differentiatePos``) and
    ``J = I``, so ``J dq = -gain e`` asks for ``dq = gain (q_posture (-) q)``. This one
    takes the difference with Pinocchio,
    ``e = -map(posture_difference(model, q, q_posture, free))``
    (``JointMap.v_to_mujoco``, ``controllers.base.posture_difference``: ``pin.difference``
    without a mobile base's entries), as the CJM's ``qd_posture`` does. For 1-dof joints the
    two are the same numbers; on a planar base MuJoCo's difference is the world-frame
    ``(dx, dy, dth)`` while Pinocchio's is the SE(2) logarithm in the base frame, and
    only the latter makes mink's posture the CJM's (docs/design.md section 11).
    """

    def __init__(self, model: pin.Model, joints: JointMap, posture: np.ndarray,
                 cost: float, gain: float,
                 difference: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        super().__init__(cost=np.full(model.nv, cost), gain=gain, lm_damping=0.0)
        self.joints = joints
        self.posture = posture
        self.difference = difference  # posture_difference on the controller's model
        self._q_pin = np.empty(model.nq)
        self._identity = np.eye(model.nv)

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        """``e = -(q_posture (-) q)`` (nv,), MuJoCo velocity coordinates."""
        q_mj = configuration.q
        q_pin = self.joints.q_to_pinocchio(q_mj, out=self._q_pin)
        return -self.joints.v_to_mujoco(self.difference(q_pin, self.posture), q_mj)

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        """``J = I`` (nv x nv)."""
        return self._identity


class DampingTask(mink.Task):
    """The CJM's damping as a mink task: ``|D dq|^2`` (:mod:`controllers.optimization.task_damping`),
    ``D`` in MuJoCo columns, padded with zero rows to the task's size; error 0."""

    def __init__(self, size: int, nv: int) -> None:
        super().__init__(cost=np.ones(size), gain=1.0, lm_damping=0.0)
        self.rows = np.zeros((size, nv))
        self._error = np.zeros(size)

    def set_rows(self, rows: np.ndarray) -> None:
        self.rows[:] = 0.0
        self.rows[:rows.shape[0]] = rows

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        return self._error

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        return self.rows

