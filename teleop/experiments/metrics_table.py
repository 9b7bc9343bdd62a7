"""The comparison's table: the numeric columns of a metrics document (the terminal's
table after ``teleop compare``, report.html's, docs/results.md's), and the steps by status."""

from __future__ import annotations

from typing import Callable

#: The table's numeric columns: header, metrics key, format (a callable on the value).
TABLE_COLUMNS: tuple[tuple[str, str, Callable[[float], str]], ...] = (
    ("constraint err max (m)", "constraint_error_max_m", lambda v: f"{v:.1e}"),
    ("RMS (m)", "constraint_error_rms_m", lambda v: f"{v:.1e}"),
    ("residual max (m/s)", "constraint_velocity_residual_max_mps", lambda v: f"{v:.1e}"),
    ("C v_c max (m/s)", "constraint_velocity_max_mps", lambda v: f"{v:.1e}"),
    ("EE pos RMS (mm)", "ee_position_error_rms_m", lambda v: f"{1e3 * v:.3f}"),
    ("EE ori RMS (mrad)", "ee_orientation_error_rms_rad", lambda v: f"{1e3 * v:.3f}"),
    ("limit viol (rad)", "joint_limit_violation_max_rad", lambda v: f"{v:.3f}"),
    ("failed", "failed_steps", lambda v: f"{v}"),
    ("step median (us)", "step_time_median_us", lambda v: f"{v:.0f}"),
    ("step p99 (us)", "step_time_p99_us", lambda v: f"{v:.0f}"),
    ("qd dev max (rad/s)", "joint_velocity_deviation_max_radps", lambda v: f"{v:.1e}"),
)


#: The resolution of each column's measure: two values closer than this are the same
#: measure (double rounding on metre-scale kinematics and on the steps' integration is
#: about 1e-15; the resolution leaves three orders above it); a count's is one.
RESOLUTION: dict[str, float] = {
    "constraint_error_max_m": 1e-12, "constraint_error_rms_m": 1e-12,
    "constraint_velocity_residual_max_mps": 1e-12, "constraint_velocity_max_mps": 1e-12,
    "ee_position_error_rms_m": 1e-12, "ee_orientation_error_rms_rad": 1e-12,
    "joint_limit_violation_max_rad": 1e-12, "failed_steps": 1.0,
    "step_time_median_us": 1.0, "step_time_p99_us": 1.0,
    "joint_velocity_deviation_max_radps": 1e-12,
}


#: The second table's columns (docs/design.md section 17.3): the robot's body (null on the
#: kinematic plant, shown ``-``) and the run's smoothness.
BODY_COLUMNS: tuple[tuple[str, str, Callable[[float], str]], ...] = (
    ("hole err max (um)", "hole_error_max_m", lambda v: f"{1e6 * v:.3g}"),
    ("port force max (N)", "port_force_max_n", lambda v: f"{v:.3f}"),
    ("port force RMS (N)", "port_force_rms_n", lambda v: f"{v:.3f}"),
    ("spring at peak (N)", "port_force_peak_spring_n", lambda v: f"{v:.3f}"),
    ("damper at peak (N)", "port_force_peak_damper_n", lambda v: f"{v:.3f}"),
    ("tissue disp max (um)", "port_displacement_max_m", lambda v: f"{1e6 * v:.3g}"),
    ("EE pos max (mm)", "ee_position_error_max_m", lambda v: f"{1e3 * v:.3f}"),
    ("torque / limit max", "torque_ratio_max", lambda v: f"{v:.2f}"),
    ("saturated steps", "actuator_saturated_steps", lambda v: f"{v}"),
    ("interface faults", "interface_faults", lambda v: f"{v}"),
    ("jerk RMS (rad/s^3)", "joint_jerk_rms_radps3", lambda v: f"{v:.3g}"),
    ("EE v power > 3 Hz (%)", "ee_velocity_power_above_3hz", lambda v: f"{100 * v:.2f}"),
)


def body_cells(metrics: dict) -> list[str]:
    """One controller's row of :data:`BODY_COLUMNS` (``-`` for a value not measured)."""
    return ["-" if metrics.get(key) is None else fmt(metrics[key])
            for _, key, fmt in BODY_COLUMNS]


def format_body_table(document: dict) -> str:
    """The body and smoothness table (Markdown), after :func:`format_table` on the terminal."""
    headers = [header for header, _, _ in BODY_COLUMNS]
    lines = ["| controller | " + " | ".join(headers) + " |", "|" + "---|" * (len(headers) + 1)]
    lines += [f"| {spec} | " + " | ".join(body_cells(m)) + " |"
              for spec, m in document["controllers"].items()]
    return "\n".join(lines)


def table_cells(metrics: dict) -> list[str]:
    """One controller's row of :data:`TABLE_COLUMNS` (``-`` for a value not computed)."""
    return ["-" if metrics[key] is None else fmt(metrics[key]) for _, key, fmt in TABLE_COLUMNS]


def table_headers(document: dict) -> list[str]:
    """The headers of :data:`TABLE_COLUMNS`, the deviation's naming its reference."""
    reference = document.get("joint_velocity_reference")
    return [header if key != "joint_velocity_deviation_max_radps" or reference is None
            else f"qd dev max vs {reference} (rad/s)" for header, key, _ in TABLE_COLUMNS]


def format_table(document: dict) -> str:
    """A short table of the headline numbers (Markdown): the terminal, docs/results.md."""
    headers = table_headers(document)
    lines = ["| controller | " + " | ".join(headers) + " | steps by status |",
             "|" + "---|" * (len(headers) + 2)]
    for spec, m in document["controllers"].items():
        lines.append(f"| {spec} | " + " | ".join(table_cells(m))
                     + f" | {format_status_counts(m['status_counts'])} |")
    if len(document["ee_frames"]) > 1 or any(len(m["constraints"]) > 1
                                             for m in document["controllers"].values()):
        lines += ["", "each EE: position RMS / max (mm); each constraint: error max (m)"]
        for spec, m in document["controllers"].items():
            parts = [f"{frame} {1e3 * e['position_error_rms_m']:.3f} / "
                     f"{1e3 * e['position_error_max_m']:.3f}"
                     for frame, e in m["end_effectors"].items()]
            parts += [f"{name} {c['error_max_m']:.1e}" for name, c in m["constraints"].items()]
            lines.append(f"  {spec}: " + "; ".join(parts))
    return "\n".join(lines)


def format_status_counts(counts: dict[str, int]) -> str:
    """``ok 9990, scaled 10``: the statuses in order of severity, zeros left out."""
    order = ("ok", "scaled", "least_squares", "constraint_degraded", "failed")
    return ", ".join(f"{status} {counts[status]}" for status in order if counts.get(status))


#: The collision table's columns (docs/design.md section 18.6): the minimum distance at the
#: true configuration, the steps below 0 and below ``d_s - 0.5 mm``, the physics plant's
#: contacts (``-`` on the kinematic plant), beside the hole and EE errors.
COLLISION_COLUMNS: tuple[tuple[str, str, Callable[[float], str]], ...] = (
    ("min distance (mm)", "minimum_distance_m", lambda v: f"{1e3 * v:.2f}"),
    ("penetrations", "penetration_steps", lambda v: f"{v}"),
    ("safety violations", "safety_violation_steps", lambda v: f"{v}"),
    ("contact steps", "contact_steps", lambda v: f"{v}"),
    ("contact depth max (mm)", "contact_depth_max_m", lambda v: f"{1e3 * v:.2f}"),
    ("hole err max (um)", "hole_error_max_m", lambda v: f"{1e6 * v:.3g}"),
    ("EE pos max (mm)", "ee_position_error_max_m", lambda v: f"{1e3 * v:.3f}"),
)


def format_collision_table(document: dict) -> str:
    """The collision avoidance table (Markdown): per controller the columns of
    :data:`COLLISION_COLUMNS` and the closest pair."""
    headers = [header for header, _, _ in COLLISION_COLUMNS]
    lines = ["| controller | " + " | ".join(headers) + " | closest pair |",
             "|" + "---|" * (len(headers) + 2)]
    for spec, m in document["controllers"].items():
        cells = ["-" if m.get(key) is None else fmt(m[key]) for _, key, fmt in COLLISION_COLUMNS]
        pair = (m.get("closest_pair") or "-").replace("|", "/")
        lines.append(f"| {spec} | " + " | ".join(cells) + f" | {pair} |")
    return "\n".join(lines)
