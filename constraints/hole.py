"""Hole (trocar, entry point): the link may slide and turn in the hole, not move across it."""

from __future__ import annotations


import numpy as np
import pinocchio as pin

from .base import (
    DEFAULT_GAIN,
    Constraint,
    ConstraintPoint,
    RobotLike,
    as_unit_vector,
    as_vector,
    default_link,
    frame_placement,
    link_axis_of,
    perpendicular_basis,
)
from .limits import MAX_POSITION_M, MAX_SPEED_M_S, MAX_TISSUE_DAMPING, MAX_TISSUE_STIFFNESS
from .validation import as_number

#: How far (m) a hole centre may lie off the link axis when a hole is built.
DEFAULT_AXIS_TOLERANCE = 1e-3

#: Lateral stiffness of the abdominal wall at a port (N/m): 1 N/mm (docs/design.md 17.2).
DEFAULT_TISSUE_STIFFNESS = 1000.0

#: Lateral damping of the abdominal wall at a port (N s/m): a 10 ms time constant with the
#: default stiffness (docs/design.md 17.2).
DEFAULT_TISSUE_DAMPING = 10.0


class Hole(Constraint):
    """Two equalities: no velocity of the link across its axis at the hole (paper 5.2).

    The link axis is the line through the origin of ``F_a`` along ``link_axis`` (link
    coordinates). The constrained point is the point of that line nearest the hole
    centre, recomputed from the geometry at every evaluation (so the contact point slides
    along the link during insertion, docs/design.md section 3): ``p = (e . c_a) e`` with
    ``c_a`` the hole centre in ``F_a`` coordinates. ``C`` holds two unit vectors
    perpendicular to ``e`` and the error is the lateral offset of the axis from the
    centre, ``C (p - c_a)``.

    Parameters
    ----------
    link : the link that passes through the hole.
    center : (3,) hole centre, world frame (m).
    link_axis : (3,) unit vector along the link, link coordinates.
    gain : drift-feedback gain K (1/s).
    velocity : (3,) world velocity of the hole centre (m/s), fed forward.
    tissue_stiffness, tissue_damping : the abdominal wall around the port, for a physics
        plant (``teleop.plants.walls``; N/m, N s/m); left out of :meth:`to_dict` at the
        defaults.
    """

    dim = 2
    has_paper_form = True
    kind = "hole"
    position_attribute = "center"
    label = "hole"
    omitted_at_default = ("tissue_stiffness", "tissue_damping")

    def __init__(
        self,
        link: str,
        center,
        link_axis=(0.0, 0.0, 1.0),
        gain: float = DEFAULT_GAIN,
        velocity=(0.0, 0.0, 0.0),
        tissue_stiffness: float = DEFAULT_TISSUE_STIFFNESS,
        tissue_damping: float = DEFAULT_TISSUE_DAMPING,
    ) -> None:
        super().__init__(link, gain)
        self._set_anchor(as_vector(center, 3, "hole center", MAX_POSITION_M),
                         as_vector(velocity, 3, "hole velocity", MAX_SPEED_M_S))
        self.tissue_stiffness = as_number(tissue_stiffness, "tissue_stiffness", 0.0,
                                          maximum=MAX_TISSUE_STIFFNESS)
        self.tissue_damping = as_number(tissue_damping, "tissue_damping", 0.0,
                                        maximum=MAX_TISSUE_DAMPING)
        self.link_axis = link_axis

    @classmethod
    def on_link(
        cls,
        robot: RobotLike,
        q: np.ndarray,
        distance: float,
        link: str | None = None,
        link_axis=None,
        gain: float = DEFAULT_GAIN,
    ) -> "Hole":
        """A hole where the link axis is now, ``distance`` m along the axis from ``F_a``.

        ``link`` defaults to the robot's ``constrained_link``, ``link_axis`` to the
        robot's axis of that link (``robot.link_axes``, else ``robot.link_axis``).
        """
        distance = as_number(distance, "distance")
        link = default_link(robot, link)
        axis = (link_axis_of(robot, link) if link_axis is None
                else as_unit_vector(link_axis, "link_axis"))
        placement = frame_placement(robot.model, q, link)
        center = placement.act(distance * axis)
        return cls(link, center, link_axis=axis, gain=gain)

    @classmethod
    def at(
        cls,
        robot: RobotLike,
        q: np.ndarray,
        center,
        link: str | None = None,
        link_axis=None,
        gain: float = DEFAULT_GAIN,
        tolerance: float = DEFAULT_AXIS_TOLERANCE,
    ) -> "Hole":
        """A hole at a world ``center`` that must lie on the link axis at ``q``.

        Raises ``ValueError`` saying by how much the centre is off the axis when the
        offset exceeds ``tolerance`` (m).
        """
        link = default_link(robot, link)
        axis = (link_axis_of(robot, link) if link_axis is None
                else as_unit_vector(link_axis, "link_axis"))
        hole = cls(link, center, link_axis=axis, gain=gain)
        placement = frame_placement(robot.model, q, link)
        offset = float(np.linalg.norm(hole.error(placement)))
        if offset > as_number(tolerance, "tolerance", 0.0):
            raise ValueError(
                f"hole centre {np.round(hole.center, 6).tolist()} is off the axis of link "
                f"{link!r} by {offset:.4g} m (tolerance {tolerance:g} m)"
            )
        return hole

    # ``hole.move_to(center, velocity)`` (inherited) moves the centre (world, m) and sets
    # its velocity (m/s) for feed-forward.

    @property
    def center(self) -> np.ndarray:
        """(3,) hole centre, world frame (m); read-only: assign a new one, or ``move_to``."""
        return self._anchor[:3]

    @center.setter
    def center(self, value: np.typing.ArrayLike) -> None:
        self._set_anchor(as_vector(value, 3, "hole center", MAX_POSITION_M), self._anchor[3:])

    @property
    def velocity(self) -> np.ndarray:
        """(3,) world velocity of the centre (m/s), fed forward; read-only like ``center``."""
        return self._anchor[3:]

    @velocity.setter
    def velocity(self, value: np.typing.ArrayLike) -> None:
        self._set_anchor(self._anchor[:3], as_vector(value, 3, "hole velocity", MAX_SPEED_M_S))

    @property
    def link_axis(self) -> np.ndarray:
        """(3,) unit vector along the link, link coordinates; read-only (assign a new one)."""
        return self._link_axis

    @link_axis.setter
    def link_axis(self, value: np.typing.ArrayLike) -> None:
        axis = as_unit_vector(value, "link_axis")
        self._C = perpendicular_basis(axis)
        self._C_perp = axis[None, :]
        self._link_axis = axis

    def _set_anchor(self, center: np.ndarray, velocity: np.ndarray) -> None:
        self._anchor = np.concatenate([center, velocity])  # read-only: a new array per change

    def _center_local(self, placement: pin.SE3) -> np.ndarray:
        return placement.actInv(self.center)

    def point(self, placement: pin.SE3) -> np.ndarray:
        return float(self.link_axis @ self._center_local(placement)) * self.link_axis

    def directions(self, placement: pin.SE3) -> np.ndarray:
        return self._C

    def free_directions(self, placement: pin.SE3) -> np.ndarray:
        return self._C_perp

    def error(self, placement: pin.SE3) -> np.ndarray:
        return -self._C @ self._center_local(placement)

    @property
    def anchor(self) -> np.ndarray:
        """``[center; velocity]`` (6,), world frame: read-only, a new array whenever either
        changes."""
        return self._anchor

    def evaluate_local(self, x: np.ndarray, f: np.ndarray | None) -> ConstraintPoint:
        """The evaluation from the centre ``x`` and its velocity ``f`` in ``F_a``
        coordinates (``f`` None at rest): ``p = (e . x) e``, ``error = -C x``,
        ``rhs = K C x + C f``, affine in ``(x, f)``."""
        error = -self._C @ x
        rhs = -self.gain * error
        if f is not None:
            rhs += self._C @ f
        return ConstraintPoint(p=float(self.link_axis @ x) * self.link_axis,
                               C=self._C, C_perp=self._C_perp, error=error, rhs=rhs)

    def evaluate(self, placement: pin.SE3) -> ConstraintPoint:
        velocity = self._anchor[3:]
        return self.evaluate_local(placement.actInv(self._anchor[:3]),
                                   placement.rotation.T @ velocity if velocity.any() else None)

    def feed_forward(self, placement: pin.SE3) -> np.ndarray:
        return self._C @ (placement.rotation.T @ self.velocity)
