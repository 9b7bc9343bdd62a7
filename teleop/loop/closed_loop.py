"""The closed teleoperation loop: operator target -> EE twist -> controller -> integrate.

One tick (docs/design.md section 5)::

    T*_f  <- T*_f exp6(alpha log6(T*_f^-1 T*))     target smoothing (browser: ~20 Hz input)
    V_ff   = log6(T*_f,prev^-1 T*_f) / dt            feed-forward: the target's own twist
    V_e    = K_p log6(T_e^-1 T*_f) + Ad V_ff         EE body twist, then saturated
    qd     = controller.solve(q, V_e)
    q     <- pin.integrate(model, q, qd dt)

and every tick records the measures of docs/design.md section 7, computed here from Pinocchio
and the constraints themselves, not taken from the controller's own report.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.kinematics import frame_placement

#: Columns of the per-step record, in order (see :class:`StepRecord`).
RECORD_FIELDS = (
    "t", "constraint_error", "constraint_velocity_residual", "barrier_penetration",
    "ee_position_error", "ee_orientation_error", "joint_limit_violation", "failed",
    "step_time_us", "tick_time_us",
)


@dataclass(frozen=True)
class LoopConfig:
    """Closed-loop settings.

    Attributes
    ----------
    rate : control rate (Hz); ``dt = 1 / rate``.
    kp : pose-error gain (1/s) of ``V_e = K_p log6(T_e^-1 T*)``.
    max_linear_speed, max_angular_speed : saturation of the commanded twist (m/s, rad/s);
        the twist is scaled uniformly so its direction is kept.
    target_time_constant : first-order smoothing of the operator target (s); 0 = none.
    feed_forward : add the target's own twist to the command.
    """

    rate: float = 1000.0
    kp: float = 20.0
    max_linear_speed: float = 0.25
    max_angular_speed: float = 1.5
    target_time_constant: float = 0.0
    feed_forward: bool = True

    def __post_init__(self) -> None:
        for name in ("rate", "kp", "max_linear_speed", "max_angular_speed"):
            value = getattr(self, name)
            if not math.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be finite and > 0, got {value}")
        if not math.isfinite(self.target_time_constant) or self.target_time_constant < 0:
            raise ValueError(f"target_time_constant must be >= 0, got {self.target_time_constant}")

    @property
    def dt(self) -> float:
        return 1.0 / self.rate


@dataclass
class StepRecord:
    """What one tick measured. Errors in m / rad, velocities in m/s, times in us."""

    t: float
    constraint_error: float  # max over equality constraints of |e|
    constraint_velocity_residual: float  # max |C v_c - (-K e + ff)| over equalities
    barrier_penetration: float  # max depth behind a barrier (0 on the allowed side)
    ee_position_error: float
    ee_orientation_error: float
    joint_limit_violation: float  # max over joints of the distance past a limit (rad)
    failed: bool
    step_time_us: float
    tick_time_us: float
    constraint_velocity: np.ndarray = field(repr=False)  # C v_c of the first equality
    desired_linear_velocity: np.ndarray = field(repr=False)  # world frame
    actual_linear_velocity: np.ndarray = field(repr=False)  # world frame
    status: str = "ok"  # the controller's step status (controllers.StepStatus value)
    message: str = ""


@dataclass
class PendingStep:
    """What :meth:`TeleopLoop.advance` computed, waiting for the end-of-period measures."""

    target: pin.SE3
    tick_start: int  # perf_counter_ns
    step_time_us: float
    status: str
    message: str
    residual: float
    constraint_velocity: np.ndarray
    desired_linear_velocity: np.ndarray
    actual_linear_velocity: np.ndarray


def saturate_twist(twist: np.ndarray, max_linear: float, max_angular: float) -> np.ndarray:
    """Scale ``[v; w]`` uniformly so that ``|v| <= max_linear`` and ``|w| <= max_angular``."""
    scale = min(1.0, max_linear / max(np.linalg.norm(twist[:3]), 1e-300),
                max_angular / max(np.linalg.norm(twist[3:]), 1e-300))
    return twist * scale


class TeleopLoop:
    """State and one-tick logic of the closed loop; no threads, no I/O.

    Parameters
    ----------
    robot : a ``teleop.Robot``.
    controller : any controller with ``solve(q, twist)``, ``info`` and ``set_constraints``.
    q0 : initial configuration (default ``robot.q_home``).
    config : :class:`LoopConfig`.
    """

    def __init__(self, robot, controller, q0: np.ndarray | None = None,
                 config: LoopConfig | None = None) -> None:
        self.robot = robot
        self.model: pin.Model = robot.model
        self.data: pin.Data = self.model.createData()
        self.controller = controller
        self.config = config or LoopConfig()
        self.ee_frame_id = self.model.getFrameId(robot.ee_frame)
        self.q = np.array(robot.q_home if q0 is None else q0, dtype=float)
        self.t = 0.0
        self._filtered_target: pin.SE3 | None = None
        self._previous_target: pin.SE3 | None = None
        self.last_qd = np.zeros(self.model.nv)

    # -- state -------------------------------------------------------------------------

    @property
    def constraints(self) -> list[Constraint]:
        return self.controller.constraints

    def set_constraints(self, constraints: Sequence[Constraint]) -> None:
        self.controller.set_constraints(list(constraints))

    def ee_placement(self, q: np.ndarray | None = None) -> pin.SE3:
        """World placement of the EE at ``q`` (default: the current state)."""
        return frame_placement(self.model, self.q if q is None else q, self.ee_frame_id, self.data)

    def reset(self, q0: np.ndarray | None = None) -> None:
        """Back to ``q0`` (default home), forgetting the target history."""
        self.q = np.array(self.robot.q_home if q0 is None else q0, dtype=float)
        self.t = 0.0
        self._filtered_target = None
        self._previous_target = None
        self.last_qd = np.zeros(self.model.nv)

    # -- one tick ----------------------------------------------------------------------

    def filter_target(self, target: pin.SE3) -> pin.SE3:
        """First-order smoothing on SE(3) (identity when ``target_time_constant == 0``)."""
        tau = self.config.target_time_constant
        if self._filtered_target is None or tau == 0.0:
            self._filtered_target = target.copy()
        else:
            alpha = 1.0 - math.exp(-self.config.dt / tau)
            step = pin.log6(self._filtered_target.actInv(target)).vector * alpha
            self._filtered_target = self._filtered_target * pin.exp6(step)
        return self._filtered_target

    def command(self, ee: pin.SE3, target: pin.SE3) -> np.ndarray:
        """EE body twist ``K_p log6(T_e^-1 T*) + Ad_(T_e^-1 T*) V_ff``, saturated."""
        error = ee.actInv(target)
        twist = self.config.kp * pin.log6(error).vector
        if self.config.feed_forward and self._previous_target is not None:
            target_twist = pin.log6(self._previous_target.actInv(target)).vector / self.config.dt
            twist += error.action @ target_twist
        return saturate_twist(twist, self.config.max_linear_speed, self.config.max_angular_speed)

    def tick(self, target: pin.SE3,
             advance_geometry: Callable[[float], None] | None = None) -> StepRecord:
        """Advance one control period towards ``target`` and measure it.

        The measures are taken at the end of the period, against the geometry of that
        instant: ``advance_geometry(t)`` (when moving geometry is given) is called with the
        new time after the integration, to move the constraints there first.
        """
        step = self.advance(target)
        if advance_geometry is not None:
            advance_geometry(self.t)
        return self.measure(step)

    def advance(self, target: pin.SE3) -> "PendingStep":
        """The first half of :meth:`tick`: command, solve, integrate (no end measures)."""
        tick_start = time.perf_counter_ns()
        dt = self.config.dt
        model, data = self.model, self.data
        target = self.filter_target(target)
        pin.computeJointJacobians(model, data, self.q)
        pin.updateFramePlacements(model, data)
        ee = data.oMf[self.ee_frame_id].copy()
        twist = self.command(ee, target)
        self._previous_target = target.copy()

        solve_start = time.perf_counter_ns()
        try:
            qd = self.controller.solve(self.q, twist)
            status = self.controller.info.status.value
            message = self.controller.info.message
        except ValueError as error:  # refused input: hold still, say why
            qd, status, message = np.zeros(model.nv), "failed", str(error)
        step_time = (time.perf_counter_ns() - solve_start) * 1e-3
        if not np.isfinite(qd).all():  # never integrate a non-finite command
            qd, status, message = np.zeros(model.nv), "failed", "non-finite command replaced by zero"

        # measures at the configuration the command was computed for
        residual, velocity = self._constraint_velocity(qd)
        ee_jacobian = pin.getFrameJacobian(model, data, self.ee_frame_id, pin.LOCAL)
        rotation = ee.rotation

        self.q = pin.integrate(model, self.q, qd * dt)
        self.last_qd = qd
        self.t += dt
        return PendingStep(target=target, tick_start=tick_start, step_time_us=step_time,
                           status=status, message=message, residual=residual,
                           constraint_velocity=velocity,
                           desired_linear_velocity=rotation @ twist[:3],
                           actual_linear_velocity=rotation @ (ee_jacobian[:3] @ qd))

    def measure(self, step: "PendingStep") -> StepRecord:
        """The second half of :meth:`tick`: the measures at the end of the period."""
        model, data = self.model, self.data
        error, penetration = self._constraint_errors()
        ee_now = data.oMf[self.ee_frame_id]
        target = step.target
        position_error = float(np.linalg.norm(ee_now.translation - target.translation))
        orientation_error = float(np.linalg.norm(pin.log3(ee_now.rotation.T @ target.rotation)))
        violation = float(max(0.0, np.max(self.q - model.upperPositionLimit),
                              np.max(model.lowerPositionLimit - self.q)))
        return StepRecord(
            t=self.t, constraint_error=error, constraint_velocity_residual=step.residual,
            barrier_penetration=penetration, ee_position_error=position_error,
            ee_orientation_error=orientation_error, joint_limit_violation=violation,
            failed=step.status == "failed", step_time_us=step.step_time_us,
            tick_time_us=(time.perf_counter_ns() - step.tick_start) * 1e-3,
            constraint_velocity=step.constraint_velocity,
            desired_linear_velocity=step.desired_linear_velocity,
            actual_linear_velocity=step.actual_linear_velocity, status=step.status,
            message=step.message,
        )

    def _constraint_velocity(self, qd: np.ndarray) -> tuple[float, np.ndarray]:
        """max |A qd - b| over the equalities and ``C v_c`` of the first one."""
        residual, velocity = 0.0, np.zeros(2)
        first = True
        for constraint, frame in zip(self.constraints, self.controller.constraint_frames):
            if not constraint.is_equality:
                continue
            A, b = constraint.rows(self.model, self.data, frame)
            achieved = A @ qd
            residual = max(residual, float(np.max(np.abs(achieved - b))))
            if first:
                velocity, first = achieved, False
        return residual, velocity

    def _constraint_errors(self) -> tuple[float, float]:
        """After integration: max |e| over equalities, max inequality (barrier)
        penetration, each the constraint's own ``violation``."""
        pin.framesForwardKinematics(self.model, self.data, self.q)  # every frame at once
        error, penetration = 0.0, 0.0
        for constraint, frame in zip(self.constraints, self.controller.constraint_frames):
            violation = constraint.violation(self.data.oMf[frame])
            if constraint.is_equality:
                error = max(error, violation)
            else:
                penetration = max(penetration, violation)
        return error, penetration

