"""Barrier: a point of the link stays on the positive side of a plane (one inequality)."""

from __future__ import annotations


import pinocchio as pin

from .gain_rule import GainRule
from .plane import Plane

#: Default barrier gain (1/s): the point may approach the plane at most at ``K d`` m/s.
DEFAULT_BARRIER_GAIN = 100.0


class Barrier(Plane):
    """One inequality: ``n . v_c >= -K d + n . v_plane`` (a velocity damper).

    ``d`` is the signed distance of the link point from the plane, positive on the
    allowed side. Far from the plane the row is inactive; the point approaches it
    exponentially, at most at ``K d`` m/s, and never crosses it in continuous time (in
    discrete time at period ``dt``, for ``K dt < 1``, which the controllers check). This
    is the row ``-n^T v_c <= gamma d / dt`` of docs/design.md section 12, with
    ``gamma = K dt``. A point already on the wrong
    side (``d < 0``) is pushed back at ``K |d|``.

    The QP uses the row as an inequality; the CJM switches it on as the plane equality
    ``n . v_c = -K d + n . v_plane`` when its unconstrained solution would violate it.
    """

    is_equality = False
    default_gain = DEFAULT_BARRIER_GAIN
    kind = "barrier"
    label = "barrier"
    #: ``K dt < 1`` (exclusive, like every gain bound here): the point never crosses
    #: the plane in discrete time
    gain_rule = GainRule(max_gain_period=1.0)

    # ``Barrier.through_link_point(robot, q, normal, ..., plane_point=...)`` (inherited):
    # the point must be on the allowed side at ``q``; more than ``tolerance`` m behind the
    # plane raises ``ValueError`` saying how far.

    def _check_start(self, signed_distance: float, tolerance: float) -> None:
        if signed_distance < -tolerance:
            raise ValueError(
                f"link point is {-signed_distance:.4g} m on the wrong side of the barrier "
                f"(tolerance {tolerance:g} m)"
            )

    def penetration(self, placement: pin.SE3) -> float:
        """How far (m) the point is behind the barrier; 0 on the allowed side."""
        return max(0.0, -self.signed_distance(placement))

    def violation(self, placement: pin.SE3) -> float:
        """The :meth:`penetration`: a barrier is satisfied anywhere on its allowed side."""
        return self.penetration(placement)
