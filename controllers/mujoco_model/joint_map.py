"""Pinocchio's coordinates and MuJoCo's, joints matched by name (docs/design.md 4.8, 11.3)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class PlanarBase:
    """Pinocchio's planar root joint as MuJoCo's slide x, slide y and hinge z on the root body.

    Pinocchio's configuration is ``(x, y, cos th, sin th)`` and its velocity
    ``(v_x, v_y, w)`` is in the *base* frame (``LOCAL``); MuJoCo's slides move along the
    world's axes, so its configuration is ``(x, y, th)`` and its velocity
    ``(x', y', th') = P(th) (v_x, v_y, w)`` with ``P(th) = diag(R(th), 1)``, ``R(th)`` the
    2D rotation (docs/design.md section 11). ``P`` is orthogonal: a matrix ``M`` acting on
    Pinocchio's base velocity acts on MuJoCo's as ``M P(th)^T``.

    Attributes: the first configuration and velocity index of the base in each model.
    """

    pin_q: int
    pin_v: int
    mj_q: int
    mj_v: int

    def heading(self, q_mj: np.ndarray) -> float:
        """The base's heading ``th`` (rad) in a MuJoCo ``qpos``."""
        return float(q_mj[self.mj_q + 2])

    def rotation(self, q_mj: np.ndarray) -> np.ndarray:
        """``P(th)`` (3 x 3): Pinocchio's base velocity to MuJoCo's."""
        heading = self.heading(q_mj)
        cos, sin = math.cos(heading), math.sin(heading)
        return np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])

    def q_to_mujoco(self, q_pin: np.ndarray, out: np.ndarray) -> None:
        """``(x, y, cos, sin)`` into ``(x, y, atan2(sin, cos))``."""
        x, y, cos, sin = q_pin[self.pin_q:self.pin_q + 4]
        out[self.mj_q:self.mj_q + 3] = x, y, math.atan2(sin, cos)

    def q_to_pinocchio(self, q_mj: np.ndarray, out: np.ndarray) -> None:
        """``(x, y, th)`` into ``(x, y, cos th, sin th)``."""
        x, y, heading = q_mj[self.mj_q:self.mj_q + 3]
        out[self.pin_q:self.pin_q + 4] = x, y, math.cos(heading), math.sin(heading)

    def v_to_pinocchio(self, v_mj: np.ndarray, q_mj: np.ndarray, out: np.ndarray) -> None:
        """Base-frame ``(v_x, v_y, w) = P^T (x', y', th')``."""
        out[self.pin_v:self.pin_v + 3] = self.rotation(q_mj).T @ v_mj[self.mj_v:self.mj_v + 3]

    def v_to_mujoco(self, v_pin: np.ndarray, q_mj: np.ndarray, out: np.ndarray) -> None:
        """World-frame ``(x', y', th') = P (v_x, v_y, w)``."""
        out[self.mj_v:self.mj_v + 3] = self.rotation(q_mj) @ v_pin[self.pin_v:self.pin_v + 3]

    def columns_to_mujoco(self, matrix_pin: np.ndarray, q_mj: np.ndarray,
                          out: np.ndarray) -> None:
        """The base's columns of ``matrix_pin`` times ``P^T``, into MuJoCo's base columns."""
        out[:, self.mj_v:self.mj_v + 3] = (
            matrix_pin[:, self.pin_v:self.pin_v + 3] @ self.rotation(q_mj).T)


@dataclass(frozen=True)
class JointMap:
    """Maps between Pinocchio and MuJoCo coordinates, joints matched by name.

    For every 1-dof joint ``k`` (revolute or prismatic): ``q_mj[mj_q[k]] = q_pin[pin_q[k]]``
    and ``v_mj[mj_v[k]] = v_pin[pin_v[k]]``. A planar root joint, if any, is ``base``
    (:class:`PlanarBase`): its velocity map turns with the heading, so the velocity and
    column maps take the MuJoCo configuration ``q_mj`` they apply at. A continuous joint
    (Pinocchio's unbounded revolute, ``(cos, sin)`` at ``continuous_pin_q``) is an angle
    at ``continuous_mj_q`` in MuJoCo; its velocity maps like any 1-dof joint's. Built-in fixed-base
    robots have 8 revolute joints in the same order in both models (``identity``, the
    maps then only copy), but nothing here assumes it.
    """

    names: tuple[str, ...]
    pin_q: np.ndarray
    pin_v: np.ndarray
    mj_q: np.ndarray
    mj_v: np.ndarray
    identity: bool
    base: PlanarBase | None = None
    continuous_pin_q: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    continuous_mj_q: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    def q_to_mujoco(self, q_pin: np.ndarray, out: np.ndarray) -> np.ndarray:
        """MuJoCo ``qpos`` from a Pinocchio configuration, written into ``out``."""
        if self.identity:
            out[:] = q_pin
            return out
        out[self.mj_q] = q_pin[self.pin_q]
        cos, sin = q_pin[self.continuous_pin_q], q_pin[self.continuous_pin_q + 1]
        out[self.continuous_mj_q] = np.arctan2(sin, cos)
        if self.base is not None:
            self.base.q_to_mujoco(q_pin, out)
        return out

    def q_to_pinocchio(self, q_mj: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Pinocchio configuration from a MuJoCo ``qpos``, written into ``out``."""
        if self.identity:
            out[:] = q_mj
            return out
        out[self.pin_q] = q_mj[self.mj_q]
        angle = q_mj[self.continuous_mj_q]
        out[self.continuous_pin_q], out[self.continuous_pin_q + 1] = np.cos(angle), np.sin(angle)
        if self.base is not None:
            self.base.q_to_pinocchio(q_mj, out)
        return out

    def v_to_pinocchio(self, v_mj: np.ndarray, q_mj: np.ndarray) -> np.ndarray:
        """Pinocchio velocity from a MuJoCo one at ``q_mj`` (``v_mj`` itself when
        ``identity``)."""
        if self.identity:
            return v_mj
        out = np.empty(len(v_mj))  # nv is the same in both models
        out[self.pin_v] = v_mj[self.mj_v]
        if self.base is not None:
            self.base.v_to_pinocchio(v_mj, q_mj, out)
        return out

    def v_to_mujoco(self, v_pin: np.ndarray, q_mj: np.ndarray) -> np.ndarray:
        """MuJoCo velocity from a Pinocchio one at ``q_mj`` (``v_pin`` itself when
        ``identity``)."""
        if self.identity:
            return v_pin
        out = np.empty(len(v_pin))
        out[self.mj_v] = v_pin[self.pin_v]
        if self.base is not None:
            self.base.v_to_mujoco(v_pin, q_mj, out)
        return out

    def columns_to_mujoco(self, matrix_pin: np.ndarray, q_mj: np.ndarray) -> np.ndarray:
        """A matrix acting on Pinocchio velocities, made to act on MuJoCo ones at ``q_mj``:
        ``M_mj v_mj = M_pin v_pin`` (``matrix_pin`` itself when ``identity``)."""
        if self.identity:
            return matrix_pin
        out = np.empty_like(matrix_pin)
        out[:, self.mj_v] = matrix_pin[:, self.pin_v]
        if self.base is not None:
            self.base.columns_to_mujoco(matrix_pin, q_mj, out)
        return out
