"""Plane: a point of the link may move in a plane but not along its normal (paper 5.1)."""

from __future__ import annotations


import numpy as np
import pinocchio as pin

from .base import (
    DEFAULT_GAIN,
    Constraint,
    RobotLike,
    as_unit_vector,
    as_vector,
    link_point_at,
    perpendicular_basis,
)
from .limits import MAX_POSITION_M, MAX_SPEED_M_S
from .validation import as_number

#: How far (m) the link point may be from the plane when a plane is built.
DEFAULT_PLANE_TOLERANCE = 1e-3


class Plane(Constraint):
    """One equality: the material point ``p`` of a link keeps zero velocity along ``n``.

    The point is fixed on the link (link coordinates). The error is its signed distance
    to the plane, ``e = n . (x_c - x_0)``, and ``C = (R_a^T n)^T``.

    Parameters
    ----------
    link : the link carrying the point.
    link_point : (3,) the point, link coordinates (m).
    plane_point : (3,) a point of the plane, world frame (m).
    normal : (3,) unit normal of the plane, world frame.
    gain : drift-feedback gain K (1/s).
    velocity : (3,) world velocity of the plane (translation only), fed forward.
    """

    dim = 1
    #: drift-feedback gain used when none is given (a subclass may set its own)
    default_gain: float = DEFAULT_GAIN
    kind = "plane"
    position_attribute = "plane_point"
    world_directions = ("normal", "velocity")
    label = "plane"

    def __init__(
        self,
        link: str,
        link_point,
        plane_point,
        normal,
        gain: float | None = None,
        velocity=(0.0, 0.0, 0.0),
    ) -> None:
        super().__init__(link, self.default_gain if gain is None else gain)
        self.link_point = as_vector(link_point, 3, "link_point", MAX_POSITION_M)
        self.plane_point = as_vector(plane_point, 3, "plane_point", MAX_POSITION_M)
        self.normal = as_unit_vector(normal, "plane normal")
        self.velocity = as_vector(velocity, 3, "plane velocity", MAX_SPEED_M_S)

    @classmethod
    def through_link_point(
        cls,
        robot: RobotLike,
        q: np.ndarray,
        normal,
        link_point=None,
        distance: float | None = None,
        link: str | None = None,
        gain: float | None = None,
        tolerance: float = DEFAULT_PLANE_TOLERANCE,
        plane_point=None,
        offset: float = 0.0,
    ) -> "Plane":
        """A plane through a link point as it is at ``q``, with a world ``normal``.

        Give the point either as ``link_point`` (link coordinates) or as ``distance``
        metres along the robot's ``link_axis``. With ``plane_point`` given, the plane
        passes there instead; with ``offset``, ``offset`` m behind the point along the
        unit ``normal`` (not both: ``ValueError``). A link point farther than ``tolerance``
        from the plane raises ``ValueError`` saying how far (a barrier's: behind it).
        """
        link, link_point, placement = link_point_at(robot, q, link, link_point, distance)
        point_world = placement.act(link_point)
        offset = as_number(offset, f"{cls.label} offset")
        if plane_point is not None and offset != 0.0:
            raise ValueError(f"give {cls.label} plane_point or offset, not both (the offset "
                             "moves the plane from the link point, plane_point places it)")
        if plane_point is None:
            plane_point = point_world
            if offset != 0.0:
                plane_point = point_world - offset * as_unit_vector(normal, f"{cls.label} normal")
        plane = cls(link, link_point, plane_point, normal, gain=gain)
        plane._check_start(plane.signed_distance(placement), as_number(tolerance, "tolerance", 0.0))
        return plane

    def _check_start(self, signed_distance: float, tolerance: float) -> None:
        if abs(signed_distance) > tolerance:
            raise ValueError(
                f"link point is {abs(signed_distance):.4g} m from the plane "
                f"(tolerance {tolerance:g} m): the point must lie on the plane"
            )

    # ``plane.move_to(plane_point, velocity)`` (inherited) moves the plane (a world point
    # on it, m) and sets its velocity (m/s).

    def point(self, placement: pin.SE3) -> np.ndarray:
        return self.link_point

    def directions(self, placement: pin.SE3) -> np.ndarray:
        return (placement.rotation.T @ self.normal)[None, :]

    def free_directions(self, placement: pin.SE3) -> np.ndarray:
        return perpendicular_basis(placement.rotation.T @ self.normal)

    def signed_distance(self, placement: pin.SE3) -> float:
        """Signed distance (m) of the link point from the plane, positive along ``n``."""
        return float(self.normal @ (placement.act(self.link_point) - self.plane_point))

    def error(self, placement: pin.SE3) -> np.ndarray:
        return np.array([self.signed_distance(placement)])

    def feed_forward(self, placement: pin.SE3) -> np.ndarray:
        return np.array([float(self.normal @ self.velocity)])
