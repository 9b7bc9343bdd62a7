"""One controller's run as columns, and its summary metrics (the keys of metrics.json)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: per-controller keys of metrics.json, in order (documented in README and metrics.schema.json)
METRIC_KEYS = (
    "constraint_error_max_m", "constraint_error_rms_m",
    "constraint_velocity_residual_max_mps", "barrier_penetration_max_m",
    "ee_position_error_max_m", "ee_position_error_rms_m",
    "ee_orientation_error_max_rad", "ee_orientation_error_rms_rad",
    "joint_limit_violation_max_rad", "failed_steps",
    "step_time_median_us", "step_time_p99_us", "step_time_max_us", "tick_time_median_us",
)


@dataclass
class RunResult:
    """One controller's run: per-step columns and what went wrong."""

    controller: str
    columns: dict[str, np.ndarray]
    constraint_velocity: np.ndarray  # (steps, k) C v_c of the first equality
    desired_linear_velocity: np.ndarray  # (steps, 3) world frame
    actual_linear_velocity: np.ndarray  # (steps, 3) world frame
    failure_messages: list[str] = field(default_factory=list)
    status_counts: dict[str, int] = field(default_factory=dict)  # steps per step status

    @property
    def steps(self) -> int:
        return len(self.columns["t"])

    def metrics(self) -> dict[str, float | int | str | None]:
        """The summary of docs/design.md section 7 (units in the key names)."""
        c = self.columns

        def rms(x: np.ndarray) -> float:
            return float(np.sqrt(np.mean(np.square(x)))) if x.size else 0.0

        def top(x: np.ndarray) -> float:
            return float(np.max(x)) if x.size else 0.0

        step = c["step_time_us"]
        return {
            "constraint_error_max_m": top(c["constraint_error"]),
            "constraint_error_rms_m": rms(c["constraint_error"]),
            "constraint_velocity_residual_max_mps": top(c["constraint_velocity_residual"]),
            "barrier_penetration_max_m": top(c["barrier_penetration"]),
            "ee_position_error_max_m": top(c["ee_position_error"]),
            "ee_position_error_rms_m": rms(c["ee_position_error"]),
            "ee_orientation_error_max_rad": top(c["ee_orientation_error"]),
            "ee_orientation_error_rms_rad": rms(c["ee_orientation_error"]),
            "joint_limit_violation_max_rad": top(c["joint_limit_violation"]),
            "failed_steps": int(np.sum(c["failed"])),
            "step_time_median_us": float(np.median(step)) if step.size else 0.0,
            "step_time_p99_us": float(np.percentile(step, 99)) if step.size else 0.0,
            "step_time_max_us": top(step),
            "tick_time_median_us": float(np.median(c["tick_time_us"])) if step.size else 0.0,
            "first_failure": self.failure_messages[0] if self.failure_messages else None,
            "status_counts": dict(self.status_counts),
        }


