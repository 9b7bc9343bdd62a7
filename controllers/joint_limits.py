"""The joint-velocity box every controller's command must stay in (docs/design.md section 8)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from constraints.validation import as_number

from .joint_acceleration import acceleration_box, as_acceleration_limit, braking_speed, jerk_box

#: Fraction ``g`` of the distance to a position limit a joint may cover in one period.
DEFAULT_LIMIT_GAIN = 0.95


class JointBounds:
    """``lower <= qd <= upper`` from the velocity limits and the position limits at ``q``.

    ::

        lower_i = max(-qd_max_i, g (q_min_i - q_i) / dt)
        upper_i = min( qd_max_i, g (q_max_i - q_i) / dt)

    so ``q + qd dt`` stays inside the position limits (``g < 1`` keeps a margin). With
    acceleration limits ``a`` the position bound is the braking-aware one of
    :func:`controllers.joint_acceleration.braking_speed` (at most the one above), and
    :meth:`box` given the previous command ``qd_prev`` also intersects the acceleration box
    ``[qd_prev - a dt, qd_prev + a dt]`` (docs/design.md section 8.4). A joint
    already past a position limit may only come back, at most at its velocity limit.
    Unlimited joints (no finite limit in the model) get ``+-inf``; position limits apply
    to one-dimensional joints only (revolute, prismatic), where ``q`` and ``qd`` share
    their index meaning.

    Parameters
    ----------
    model : the Pinocchio model (its ``velocityLimit`` and position limits).
    dt : control period (s).
    limit_gain : ``g`` in (0, 1].
    position_limits, velocity_limits : which limits apply.
    acceleration_limit : (nv,) rad/s^2 (m/s^2 for prismatic and base translations), ``inf``
        for none on a joint; None: no acceleration limit.
    """

    def __init__(self, model: pin.Model, dt: float = 1e-3,
                 limit_gain: float = DEFAULT_LIMIT_GAIN, position_limits: bool = True,
                 velocity_limits: bool = True, acceleration_limit=None,
                 jerk_limit=None) -> None:
        self.dt = as_number(dt, "dt", positive=True)
        self.limit_gain = as_number(limit_gain, "limit_gain", positive=True, maximum=1.0)
        self.position_limits = bool(position_limits)
        self.velocity_limits = bool(velocity_limits)
        nv = model.nv
        velocity = np.asarray(model.velocityLimit, dtype=float).copy()
        velocity[~np.isfinite(velocity) | (velocity <= 0.0)] = np.inf
        #: velocity limit per joint (inf where the model gives none)
        self.velocity_limit = velocity
        #: (2, nv): the velocity box alone, ``-qd_max`` and ``qd_max`` (+-inf where none or off)
        self.velocity_box = (np.vstack([-velocity, velocity]) if self.velocity_limits
                              else np.vstack([np.full(nv, -np.inf), np.full(nv, np.inf)]))
        scalar = [joint for joint in range(1, model.njoints)
                  if model.nqs[joint] == 1 and model.nvs[joint] == 1]
        q_index = np.array([model.idx_qs[joint] for joint in scalar], dtype=int)
        v_index = np.array([model.idx_vs[joint] for joint in scalar], dtype=int)
        q_min = model.lowerPositionLimit[q_index]
        q_max = model.upperPositionLimit[q_index]
        finite = np.isfinite(q_min) & np.isfinite(q_max) & (q_max > q_min)
        #: configuration and velocity indices of the joints with finite position limits
        self.limited_q, self.limited_v = q_index[finite], v_index[finite]
        #: (2, n): ``q_min`` and ``q_max`` of those joints
        self.q_limits = np.vstack([q_min[finite], q_max[finite]])
        #: (nv,) acceleration limits (inf where none), or None
        self.acceleration_limit = as_acceleration_limit(acceleration_limit, nv)
        #: (nv,) the largest change of command per period, ``a dt``, or None
        self.acceleration_step = (None if self.acceleration_limit is None
                                  else self.acceleration_limit * self.dt)
        #: (nv,) jerk limits (inf where none), or None
        self.jerk_limit = as_acceleration_limit(jerk_limit, nv, "jerk_limit")
        if self.jerk_limit is not None and self.acceleration_limit is None:
            raise ValueError("jerk_limit needs acceleration limits: give acceleration_limit too")
        #: (nv,) the largest change of the command's change per period, ``j dt^2``, or None
        self.jerk_step = None if self.jerk_limit is None else self.jerk_limit * self.dt ** 2
        braked = (np.zeros(0, dtype=int) if self.acceleration_step is None
                  else np.flatnonzero(np.isfinite(self.acceleration_step[self.limited_v])))
        #: indices (into ``limited_v``) of the joints whose position bound brakes
        self._braked = braked
        self._braked_step = (self.acceleration_step[self.limited_v[braked]]
                             if braked.size else np.zeros(0))

    def box(self, q: np.ndarray, previous: np.ndarray | None = None,
            previous_change: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)``, each (nv,), at configuration ``q`` (new arrays); with
        ``previous`` (the last command) and acceleration limits, intersected with
        :func:`controllers.joint_acceleration.acceleration_box`; with ``previous_change``
        (the last command minus the one before) and jerk limits, then cut by
        :func:`controllers.joint_acceleration.jerk_box`."""
        box = self.velocity_box.copy()
        if self.position_limits and self.limited_v.size:
            distance = self.q_limits - q[self.limited_q]
            position = distance * (self.limit_gain / self.dt)
            if self._braked.size:
                self._brake(distance, position)
            v = self.limited_v
            box[0, v] = np.maximum(box[0, v], position[0])
            box[1, v] = np.minimum(box[1, v], position[1])
        lower, upper = box[0], box[1]
        # past a limit: the position bound points back; never faster than the velocity limit
        np.minimum(lower, self.velocity_box[1], out=lower)
        np.maximum(upper, self.velocity_box[0], out=upper)
        np.maximum(upper, lower, out=upper)
        if previous is None or self.acceleration_step is None:
            return lower, upper
        accel_lower, accel_upper = acceleration_box(lower, upper, previous, self.acceleration_step)
        lower, upper = np.maximum(lower, accel_lower), np.minimum(upper, accel_upper)
        if previous_change is None or self.jerk_step is None:
            return lower, upper
        return jerk_box(lower, upper, previous, previous_change, self.jerk_step,
                        self.velocity_box[1])

    def _brake(self, distance: np.ndarray, position: np.ndarray) -> None:
        """The braking-aware position bounds of the joints with an acceleration limit,
        inside their limits, into ``position`` (2, n)."""
        braked, step = self._braked, self._braked_step
        below, above = distance[0, braked], distance[1, braked]
        lower = np.where(below <= 0.0, -braking_speed(np.maximum(-below, 0.0), step, self.dt,
                                                      self.limit_gain), position[0, braked])
        upper = np.where(above >= 0.0, braking_speed(np.maximum(above, 0.0), step, self.dt,
                                                     self.limit_gain), position[1, braked])
        position[0, braked] = lower
        position[1, braked] = upper


class BoxTest:
    """A fast ``lower - tol <= qd <= upper + tol`` test for the common case of no binding limit.

    Every bound of :meth:`JointBounds.box` is affine in ``(qd, q)`` while ``q`` is inside
    its position limits, so the whole test is one product ``M [qd; q; 1] <= 0`` with a
    constant ``M``: one matrix product instead of the eight NumPy calls of
    :meth:`JointBounds.box` (docs/design.md section 8.2). It answers False, never wrongly
    True, when ``q`` is past a limit; the caller then computes the exact box.
    """

    def __init__(self, bounds: JointBounds, nq: int, nv: int, tolerance: float = 1e-9) -> None:
        gain = bounds.limit_gain / bounds.dt
        # slack per joint: ``tolerance`` of its velocity limit (rad/s), so a passing qd is
        # within ``limit (1 + tolerance)`` and ``q + qd dt`` within ``tolerance limit dt``
        # of a position limit; far above the rounding of ``g (q_limit - q) / dt``
        slack = [tolerance * (limit if np.isfinite(limit) else 1.0)
                 for limit in bounds.velocity_limit.tolist()]
        rows: list[np.ndarray] = []
        for v, limit in enumerate(bounds.velocity_limit.tolist()):
            if bounds.velocity_limits and np.isfinite(limit):
                for sign in (1.0, -1.0):  # sign qd_v - limit - slack <= 0
                    row = np.zeros(nv + nq + 1)
                    row[v], row[-1] = sign, -limit - slack[v]
                    rows.append(row)
        if bounds.position_limits:
            for c, v, q_min, q_max in zip(bounds.limited_q.tolist(), bounds.limited_v.tolist(),
                                          bounds.q_limits[0].tolist(), bounds.q_limits[1].tolist()):
                # qd <= g (q_max - q) / dt  and  -qd <= -g (q_min - q) / dt
                for sign, q_limit in ((1.0, q_max), (-1.0, q_min)):
                    row = np.zeros(nv + nq + 1)
                    row[v], row[nv + c] = sign, sign * gain
                    row[-1] = -sign * gain * q_limit - slack[v]
                    rows.append(row)
        #: per joint slack of the test (rad/s)
        self.slack = np.array(slack).reshape(nv)
        self._bounds = bounds
        #: ``M`` (rows, nv + nq + 1): inside the box when ``M [qd; q; 1] <= 0``
        self.matrix = np.array(rows).reshape(len(rows), nv + nq + 1)
        self._stacked = np.ones(nv + nq + 1)  # [qd; q; 1]
        self._nv = nv

    def contains(self, q: np.ndarray, qd: np.ndarray, previous: np.ndarray | None = None,
                 previous_change: np.ndarray | None = None) -> bool:
        """Whether ``qd`` (finite) is inside the box at ``q``, to the tolerance. With
        acceleration limits and ``previous`` the box is not affine in ``q`` (the braking
        bound): the exact box is computed and compared (with ``previous_change``, the jerk
        limits' too)."""
        if previous is not None and self._bounds.acceleration_step is not None:
            lower, upper = self._bounds.box(q, previous, previous_change)
            return bool(((qd >= lower - self.slack) & (qd <= upper + self.slack)).all())
        if not self.matrix.shape[0]:
            return True
        stacked = self._stacked
        stacked[:self._nv] = qd
        stacked[self._nv:-1] = q
        return max(np.dot(self.matrix, stacked).tolist()) <= 0.0
