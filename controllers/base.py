"""What every controller shares: input checks, kinematics, limits and the solve report."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.base import resolve_frame


def checked_vector(value, size: int, name: str) -> np.ndarray:
    """``value`` as a float array of shape ``(size,)``, finite, else ``ValueError`` (no copy)."""
    array = np.asarray(value, dtype=float)
    if array.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite, got {array}")
    return array


class SolverError(RuntimeError):
    """A controller could not compute a command (raised only with ``strict=True``)."""


@dataclass
class SolveInfo:
    """How the last ``solve`` went. Read it after every call: ``controller.info``.

    Attributes
    ----------
    success : False when the command is a zero-velocity fallback.
    method : ``"analytical"``, ``"general"`` (CJM) or ``"qp:<solver>"``.
    message : why it failed or fell back; empty when all went as planned.
    sigma_min : smallest singular value of the constrained Jacobian ``Jbar`` (CJM).
    damping : the damping ``lambda`` used in the damped least squares (CJM).
    scale : the factor (<= 1) applied to respect joint velocity limits (CJM).
    active_barriers : indices (into ``constraints``) of the barriers held as equalities.
    equality_residual : ``max |A qd - b|`` over the equality rows held (m/s).
    """

    success: bool = True
    method: str = ""
    message: str = ""
    sigma_min: float = float("nan")
    damping: float = 0.0
    scale: float = 1.0
    active_barriers: tuple[int, ...] = ()
    equality_residual: float = 0.0


@dataclass
class Kinematics:
    """Kinematic quantities at one configuration, computed once per step."""

    q: np.ndarray
    ee_placement: pin.SE3
    ee_jacobian: np.ndarray  # 6 x nv, LOCAL
    extras: dict = field(default_factory=dict)


class Controller(ABC):
    """Turns a desired end-effector body twist into joint velocities under constraints.

    Parameters
    ----------
    robot : a ``teleop.Robot`` (anything with ``model`` and ``ee_frame``).
    constraints : the constraints to hold (``Hole``, ``Plane``, ``PointLock``, ``Barrier``).
    strict : raise ``SolverError`` instead of returning the zero-velocity fallback.
    """

    def __init__(self, robot, constraints: Iterable[Constraint] = (), strict: bool = False) -> None:
        self.robot = robot
        self.model: pin.Model = robot.model
        self.data: pin.Data = self.model.createData()
        self.ee_frame_id = resolve_frame(self.model, robot.ee_frame)
        self.strict = bool(strict)
        self.info = SolveInfo()
        self.velocity_limit = self._finite_or_inf(self.model.velocityLimit)
        self.set_constraints(constraints)

    # -- constraints -------------------------------------------------------------------

    def set_constraints(self, constraints: Iterable[Constraint]) -> None:
        """Replace the constraint set (unknown links raise ``ValueError`` here)."""
        constraints = list(constraints)
        for constraint in constraints:
            if not isinstance(constraint, Constraint):
                raise TypeError(f"expected a Constraint, got {type(constraint).__name__}")
        self.constraints: list[Constraint] = constraints
        self.constraint_frames = [resolve_frame(self.model, c.link) for c in constraints]
        self._on_constraints_changed()

    def _on_constraints_changed(self) -> None:
        """Hook for subclasses that precompute per-constraint data."""

    # -- the step ----------------------------------------------------------------------

    def solve(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """Joint velocities (nv,) for the desired EE body twist ``[v; w]`` (``LOCAL``).

        Bad input (wrong size, NaN or inf) raises ``ValueError``. A numerical failure
        returns zeros with ``self.info.success == False`` (or raises ``SolverError`` when
        the controller is ``strict``): never a non-finite command.
        """
        q = checked_vector(q, self.model.nq, "q")
        twist = checked_vector(twist, 6, "twist")
        self.info = SolveInfo()
        kinematics = self._kinematics(q)
        try:
            qd = self._solve(kinematics, twist)
        except (np.linalg.LinAlgError, SolverError) as error:
            return self._fail(f"{type(error).__name__}: {error}")
        if not math.isfinite(float(qd.sum())):  # any NaN/inf (or overflow) poisons the sum
            return self._fail("non-finite joint velocity computed")
        return qd

    def _fail(self, message: str) -> np.ndarray:
        self.info.success = False
        self.info.message = message
        if self.strict:
            raise SolverError(message)
        return np.zeros(self.model.nv)

    def _kinematics(self, q: np.ndarray) -> Kinematics:
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        return Kinematics(
            q=q,
            ee_placement=self.data.oMf[self.ee_frame_id],
            ee_jacobian=pin.getFrameJacobian(self.model, self.data, self.ee_frame_id, pin.LOCAL),
        )

    @abstractmethod
    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        """Compute ``qd``; the kinematics in ``self.data`` are up to date."""

    # -- shared pieces -----------------------------------------------------------------

    def constraint_rows(
        self, indices: Sequence[int] | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Stacked rows ``(A, b)`` of the chosen constraints at the current kinematics."""
        if indices is None:
            indices = range(len(self.constraints))
        blocks = [self.constraints[i].rows(self.model, self.data, self.constraint_frames[i])
                  for i in indices]
        if not blocks:
            return np.zeros((0, self.model.nv)), np.zeros(0)
        return np.vstack([A for A, _ in blocks]), np.concatenate([b for _, b in blocks])

    @staticmethod
    def _finite_or_inf(limits: np.ndarray) -> np.ndarray:
        limits = np.asarray(limits, dtype=float).copy()
        limits[~np.isfinite(limits) | (limits <= 0.0)] = np.inf
        return limits

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(robot={getattr(self.robot, 'name', '?')!r}, "
                f"constraints={self.constraints!r})")
