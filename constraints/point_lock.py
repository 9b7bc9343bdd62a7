"""Point lock: a point of the link may not move at all (a spherical joint to the world)."""

from __future__ import annotations


import numpy as np
import pinocchio as pin

from .base import (
    DEFAULT_GAIN,
    Constraint,
    RobotLike,
    as_vector,
    link_point_at,
)
from .limits import MAX_POSITION_M, MAX_SPEED_M_S


class PointLock(Constraint):
    """Three equalities: the material point ``p`` of a link stays at a world ``target``.

    ``C = R_a`` (its rows are the world axes in link coordinates), so the error is the
    world offset ``x_c - target`` and ``C v_c`` the world velocity of the point.

    Parameters
    ----------
    link : the link carrying the point.
    link_point : (3,) the point, link coordinates (m).
    target : (3,) where it must stay, world frame (m).
    gain : drift-feedback gain K (1/s).
    velocity : (3,) world velocity of the target, fed forward.
    """

    dim = 3
    kind = "point_lock"
    position_attribute = "target"
    label = "point lock"

    def __init__(self, link: str, link_point, target, gain: float = DEFAULT_GAIN,
                 velocity=(0.0, 0.0, 0.0)) -> None:
        super().__init__(link, gain)
        self.link_point = as_vector(link_point, 3, "link_point", MAX_POSITION_M)
        self.target = as_vector(target, 3, "target", MAX_POSITION_M)
        self.velocity = as_vector(velocity, 3, "target velocity", MAX_SPEED_M_S)

    @classmethod
    def on_link(cls, robot: RobotLike, q: np.ndarray, link_point=None,
                distance: float | None = None, link: str | None = None,
                gain: float = DEFAULT_GAIN) -> "PointLock":
        """Lock a link point where it is at ``q`` (``link_point`` or ``distance`` on the axis)."""
        link, link_point, placement = link_point_at(robot, q, link, link_point, distance)
        return cls(link, link_point, placement.act(link_point), gain=gain)

    # ``lock.move_to(target, velocity)`` (inherited) moves the lock point (world, m) and
    # sets its velocity (m/s).

    def point(self, placement: pin.SE3) -> np.ndarray:
        return self.link_point

    def directions(self, placement: pin.SE3) -> np.ndarray:
        return placement.rotation

    def free_directions(self, placement: pin.SE3) -> np.ndarray:
        return np.zeros((0, 3))

    def error(self, placement: pin.SE3) -> np.ndarray:
        return placement.act(self.link_point) - self.target

    def feed_forward(self, placement: pin.SE3) -> np.ndarray:
        return self.velocity.copy()
