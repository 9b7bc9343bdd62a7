"""Hole (trocar, entry point): the link may slide and turn in the hole, not move across it."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .base import (
    DEFAULT_GAIN,
    Constraint,
    ConstraintPoint,
    RobotLike,
    Parametrisation,
    analytical_terms_views,
    as_unit_vector,
    as_vector,
    default_link,
    frame_placement,
    perpendicular_basis,
    resolve_frame,
)

#: How far (m) a hole centre may lie off the link axis when a hole is built.
DEFAULT_AXIS_TOLERANCE = 1e-3


class Hole(Constraint):
    """Two equalities: no velocity of the link across its axis at the hole (paper 5.2).

    The link axis is the line through the origin of ``F_a`` along ``link_axis`` (link
    coordinates). The constrained point is the point of that line nearest the hole
    centre, recomputed from the geometry at every evaluation (so the contact point slides
    along the link during insertion, DESIGN.md section 3): ``p = (e . c_a) e`` with
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
    """

    dim = 2

    def __init__(
        self,
        link: str,
        center,
        link_axis=(0.0, 0.0, 1.0),
        gain: float = DEFAULT_GAIN,
        velocity=(0.0, 0.0, 0.0),
    ) -> None:
        super().__init__(link, gain)
        self.center = as_vector(center, 3, "hole center")
        self.velocity = as_vector(velocity, 3, "hole velocity")
        self._moving = bool(self.velocity.any())
        self.link_axis = as_unit_vector(link_axis, "link_axis")
        self._C = perpendicular_basis(self.link_axis)
        self._C_perp = self.link_axis[None, :]
        self._affine: tuple | None = None  # (gain, the matrices of _affine_terms)

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

        ``link`` and ``link_axis`` default to the robot's ``constrained_link`` and
        ``link_axis``.
        """
        distance = float(distance)
        if not np.isfinite(distance):
            raise ValueError(f"distance must be finite, got {distance}")
        link = default_link(robot, link)
        axis = as_unit_vector(robot.link_axis if link_axis is None else link_axis, "link_axis")
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
        axis = as_unit_vector(robot.link_axis if link_axis is None else link_axis, "link_axis")
        hole = cls(link, center, link_axis=axis, gain=gain)
        placement = frame_placement(robot.model, q, link)
        offset = float(np.linalg.norm(hole.error(placement)))
        if offset > tolerance:
            raise ValueError(
                f"hole centre {np.round(hole.center, 6).tolist()} is off the axis of link "
                f"{link!r} by {offset:.4g} m (tolerance {tolerance:g} m)"
            )
        return hole

    def move_to(self, center, velocity=(0.0, 0.0, 0.0)) -> None:
        """Move the hole (world centre, m) and set its velocity (m/s) for feed-forward."""
        self.center = as_vector(center, 3, "hole center")
        self.velocity = as_vector(velocity, 3, "hole velocity")
        self._moving = bool(self.velocity.any())

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

    def evaluate(self, placement: pin.SE3) -> ConstraintPoint:
        center_local = placement.actInv(self.center)  # computed once for p, e and rhs
        error = -self._C @ center_local
        rhs = -self.gain * error
        if self._moving:
            rhs += self.feed_forward(placement)
        return ConstraintPoint(p=float(self.link_axis @ center_local) * self.link_axis,
                               C=self._C, C_perp=self._C_perp, error=error, rhs=rhs)

    # -- closed forms for the controllers' hot path ------------------------------------

    def _affine_terms(self) -> tuple[np.ndarray, ...]:
        """``(T_x, T_f, t_0, ...)``: the analytical terms as an affine map of two 3-vectors.

        With ``x`` the hole centre and ``f`` the hole velocity, both in ``F_a``
        coordinates, every quantity of the singularity-free parametrisation is affine in
        ``(x, f)``: ``a = e . x``, ``p = a e``, ``C^T C hat(p) = a hat(e)`` (``C^T C`` is
        the projector across ``e`` and ``hat(e)`` already maps there), ``b = K C x + C f``
        and ``V_a0 = [C^T b; 0] = [K P x + P f; 0]`` with ``P = I - e e^T``. So the flat
        terms of :meth:`Constraint.analytical_terms` are ``T_x x + T_f f + t_0`` with
        constant matrices, rebuilt only when ``gain`` changes. Three more entries are the
        same map restricted to ``R = [-b, C [I, -hat(p)]]`` (for :meth:`rows`).
        """
        cached = self._affine
        if cached is not None and cached[0] == self.gain:
            return cached[1:]
        e, C, K = self.link_axis, self._C, self.gain
        P = np.eye(3) - np.outer(e, e)
        hat_e = pin.skew(e)
        C_hat_e = C @ hat_e
        size = 6 * 5 + 7 * 2
        T_x, T_f, t_0 = np.zeros((size, 3)), np.zeros((size, 3)), np.zeros(size)
        Bx = T_x[:30].reshape(5, 6, 3).transpose(1, 0, 2)  # same layout as the views
        Rx = T_x[30:].reshape(2, 7, 3)
        Bf = T_f[:30].reshape(5, 6, 3).transpose(1, 0, 2)
        Rf = T_f[30:].reshape(2, 7, 3)
        B0, R0 = analytical_terms_views(t_0, 2)
        # B = [V_a0, S], S = [[e, a hat(e)], [0, I]]
        Bx[:3, 0] = K * P
        Bf[:3, 0] = P
        B0[:3, 1] = e
        Bx[:3, 2:] = hat_e[:, :, None] * e  # a hat(e), a = e . x
        B0[3:, 2:] = np.eye(3)
        # R = [-b, C, -a C hat(e)]
        Rx[:, 0] = -K * C
        Rf[:, 0] = -C
        R0[:, 1:4] = C
        Rx[:, 4:] = -C_hat_e[:, :, None] * e
        self._affine = (self.gain, T_x, T_f, t_0,
                        T_x[30:].copy(), T_f[30:].copy(), t_0[30:].reshape(2, 7).copy())
        return self._affine[1:]

    def analytical_terms(
        self, placement: pin.SE3, parametrisation: Parametrisation, out: np.ndarray
    ) -> None:
        if parametrisation != "nullspace":  # the paper's 1/a form is not affine
            super().analytical_terms(placement, parametrisation, out)
            return
        T_x, T_f, t_0 = self._affine_terms()[:3]
        np.dot(T_x, placement.actInv(self.center), out=out)
        out += t_0
        if self._moving:
            out += T_f @ (placement.rotation.T @ self.velocity)

    def rows(
        self, model: pin.Model, data: pin.Data, frame_id: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        # Same rows as Constraint.rows, from the closed form: A = C [I, -hat(p)] J_a.
        if frame_id is None:
            frame_id = resolve_frame(model, self.link)
        placement = pin.updateFramePlacement(model, data, frame_id)  # cheaper than data.oMf[i]
        T_x, T_f, t_0 = self._affine_terms()[3:]  # the [-b, C [I, -hat(p)]] part
        R = np.dot(T_x, placement.actInv(self.center)).reshape(2, 7)
        R += t_0
        if self._moving:
            R += np.dot(T_f, placement.rotation.T @ self.velocity).reshape(2, 7)
        jacobian = pin.getFrameJacobian(model, data, frame_id, pin.LOCAL)
        return np.dot(R[:, 1:], jacobian), -R[:, 0]

    def depth(self, placement: pin.SE3) -> float:
        """Where the link crosses the hole: metres along the axis from ``F_a``."""
        return float(self.link_axis @ self._center_local(placement))

    def feed_forward(self, placement: pin.SE3) -> np.ndarray:
        return self._C @ (placement.rotation.T @ self.velocity)
