"""``report.html``: one self-contained page per comparison (docs/design.md section 15.4).

The scenario, the robot, its plant and how it was imperfect, the package versions, the
metrics table with the best value of each column marked, the robot's body and the run's
smoothness (docs/design.md section 17.3), the steps per status, what the supervisor
measured and did (docs/design.md 5.2), the joint-velocity
agreement, what the solvers said, and every plot embedded as base64: the page needs no
network and no other file.
"""

from __future__ import annotations

import base64
import html
import platform
from importlib import metadata
from pathlib import Path
from typing import Sequence

from teleop.plants.ros2.settings import Ros2Settings

from .metrics_table import (
    BODY_COLUMNS,
    COLLISION_COLUMNS,
    RESOLUTION,
    TABLE_COLUMNS,
    body_cells,
    format_status_counts,
    table_cells,
    table_headers,
)
from .plots import Figure

#: The distributions whose versions the report lists (importlib.metadata names).
PACKAGES = ("cjm-teleop", "pin", "numpy", "qpsolvers", "proxsuite", "daqp", "osqp", "mink")

STYLE = """
body { font-family: sans-serif; margin: 2em; max-width: 1400px; color: #222; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #bbb; padding: 0.3em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
td.best { font-weight: bold; background: #e3f4e3; }
figure { margin: 2em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #444; margin-top: 0.4em; }
.note { font-size: 0.9em; color: #444; }
"""


def package_versions(packages: Sequence[str] = PACKAGES) -> dict[str, str]:
    """Installed version of each distribution (``not installed`` when absent)."""
    versions = {}
    for name in packages:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def best_rows(document: dict) -> dict[str, set[str]]:
    """Per metrics key of :data:`TABLE_COLUMNS`, the controllers whose value is the
    smallest: within the measure's :data:`RESOLUTION` of it or printed the same (ties all
    marked); none when every controller is (a difference of rounding is no ranking). The
    deviation from the reference controller is ranked without the reference (trivially 0)."""
    controllers = document["controllers"]
    reference = document.get("joint_velocity_reference")
    best: dict[str, set[str]] = {}
    for column, (_, key, fmt) in enumerate(TABLE_COLUMNS):
        shown = {spec: (m[key], table_cells(m)[column]) for spec, m in controllers.items()
                 if m[key] is not None
                 and not (key == "joint_velocity_deviation_max_radps" and spec == reference)}
        if len({text for _, text in shown.values()}) < 2:
            best[key] = set()
            continue
        smallest = min(value for value, _ in shown.values())
        tied = {spec for spec, (value, text) in shown.items()
                if text == fmt(smallest) or value - smallest <= RESOLUTION[key]}
        best[key] = tied if len(tied) < len(shown) else set()
    return best


def render_report(document: dict, figures: Sequence[Figure]) -> str:
    """The report page for a metrics document and its figures, as one HTML string."""
    e = html.escape
    imperfect = document["imperfections"]
    reference = document.get("joint_velocity_reference")
    parts = [
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        f"<title>{e(document['scenario'])}: controller comparison</title>",
        f"<style>{STYLE}</style>", "</head>", "<body>",
        f"<h1>{e(document['scenario'])}</h1>",
        f"<p>{e(document.get('description', ''))}</p>",
        "<ul>",
        f"<li>robot: <b>{e(document['robot'])}</b></li>",
        (f"<li>{document['duration_s']:g} s at {document['rate_hz']:g} Hz "
         f"({document['steps']} steps)</li>"),
        (f"<li>robot imperfections: encoder noise {imperfect['encoder_noise_rad']:g} rad, "
         f"latency {imperfect['latency_periods']} periods, joint time constant "
         f"{imperfect['joint_time_constant_s']:g} s, calibration error "
         f"{1e3 * imperfect.get('calibration_position_std_m', 0.0):g} mm, "
         f"{1e3 * imperfect.get('calibration_rotation_std_rad', 0.0):g} mrad, "
         f"seed {imperfect['seed']}</li>"),
        f"<li>plant: {e(_plant_line(document.get('plant')))}</li>",
        "</ul>",
        "<h2>Metrics</h2>", _metrics_table(document),
        '<p class="note">Bold: the smallest value of a column as printed (ties all '
        "marked; a column where every controller shows the same value has no mark)."
        + (f" qd dev: the largest |qd - qd_{e(reference)}| at the same q and twist along "
           f"{e(reference)}'s run (design 15.3)." if reference else "") + "</p>",
        "<h2>The robot's body and the run's smoothness</h2>", _body_table(document),
        '<p class="note">hole err: the holes\' axis offset on the true (simulated) '
        "configuration; port force: the abdominal wall's lateral force on the instrument, "
        "tissue disp: its displacement (design 17.2; - on the kinematic plant, which has no "
        "body); spring and damper at peak: the two parts of the port force, k |P - c| and "
        "c_d |v_perp|, at the step of its peak; interface faults: the commands the robot's "
        "interface refused or counted beyond its acceleration or jerk limits (design 17.1; - "
        "with the check off), " + html.escape(_first_faults(document)) + "; "
        "torque / limit: the largest drive torque against the URDF's effort limit; "
        "jerk: the jerkiest joint's RMS of (qd_k - 2 qd_k-1 + qd_k-2) / dt^2 over the "
        "commands; EE v power > 3 Hz: the share of the achieved EE linear velocity's power "
        "above 3 Hz (each component detrended, FFT), the worst EE.</p>",
        *(["<h2>Collision avoidance</h2>", _collision_table(document),
           '<p class="note">min distance: the smallest distance between the collision pairs '
           "on the true configuration (design 18.6); penetrations: steps below 0; safety "
           "violations: steps below d_s - 0.5 mm; contacts: the physics plant's.</p>"]
          if document.get("collisions") is not None else []),
        "<h2>Each end effector and each constraint</h2>", _parts_table(document),
        "<h2>Steps by status</h2>", _status_table(document),
        "<h2>The supervisor</h2>", _supervisor_table(document),
        "<h2>What the solvers said</h2>", _solver_messages(document),
        "<h2>Plots</h2>",
    ]
    for figure in figures:
        data = base64.b64encode(Path(figure.path).read_bytes()).decode("ascii")
        parts += ["<figure>", f"<h3>{e(figure.title)}</h3>",
                  f'<img alt="{e(figure.path.name)}" src="data:image/png;base64,{data}">',
                  f"<figcaption>{e(figure.path.name)}: {e(figure.caption)}</figcaption>",
                  "</figure>"]
    versions = package_versions()
    parts += ["<h2>Versions</h2>", "<table>", "<tr><th>package</th><th>version</th></tr>",
              f"<tr><td>python</td><td>{e(platform.python_version())}</td></tr>"]
    parts += [f"<tr><td>{e(name)}</td><td>{e(version)}</td></tr>"
              for name, version in versions.items()]
    parts += ["</table>", "</body>", "</html>"]
    return "\n".join(parts) + "\n"


def write_report(document: dict, figures: Sequence[Figure], path: str | Path) -> Path:
    """Write :func:`render_report` to ``path`` and return it."""
    path = Path(path)
    path.write_text(render_report(document, figures), encoding="utf-8")
    return path


def _metrics_table(document: dict) -> str:
    e = html.escape
    best = best_rows(document)
    rows = ["<table>", "<tr><th>controller</th>"
            + "".join(f"<th>{e(header)}</th>" for header in table_headers(document)) + "</tr>"]
    for spec, metrics in document["controllers"].items():
        cells = [f'<td class="best">{e(text)}</td>' if spec in best[key] else f"<td>{e(text)}</td>"
                 for (_, key, _), text in zip(TABLE_COLUMNS, table_cells(metrics))]
        rows.append(f"<tr><td>{e(spec)}</td>" + "".join(cells) + "</tr>")
    rows.append("</table>")
    return "\n".join(rows)


def _plant_line(plant: dict | None) -> str:
    """The plant of the runs in words (a document before schema 4: the kinematic one)."""
    if plant is None or plant["kind"] == "kinematic":
        text = "kinematic (q += qd dt)"
    elif plant["kind"] == "ros2":
        text = Ros2Settings.from_dict(plant["ros2"]).describe()
    else:
        s = plant["settings"]
        text = (f"MuJoCo physics at {s['physics_rate_hz']:g} Hz, {s['servo_bandwidth_hz']:g} Hz "
                f"servos (damping ratio {s['servo_damping_ratio']:g}), armature "
                f"{s['armature_kg_m2']:g} kg m^2, joint damping {s['joint_damping_nms']:g} "
                f"N m s/rad, payload {s['payload_kg']:g} kg, friction "
                f"{s['coulomb_friction_nm']:g} N m + {s['viscous_friction_nms']:g} N m s/rad, "
                f"gravity {'on' if s['gravity'] else 'off'}, interface limits "
                f"{s.get('interface_limits', 'off')}"
                + ("" if s.get("interface_jerk_limit_radps3") is None
                   else f" (jerk {s['interface_jerk_limit_radps3']:g} rad/s^3)"))
    stiffness = None if plant is None else plant["wall_stiffness_n_per_m"]
    return text + (", abdominal wall: each hole's own stiffness" if stiffness is None
                   else f", abdominal wall {stiffness / 1000.0:g} N/mm at every hole")


def _first_faults(document: dict) -> str:
    """Each controller's first interface fault in words, or that there was none."""
    faults = [f"{spec}: {m['interface_first_fault']}"
              for spec, m in document["controllers"].items()
              if m.get("interface_first_fault") is not None]
    return "the first: " + "; ".join(faults) if faults else "none"


def _body_table(document: dict) -> str:
    e = html.escape
    rows = ["<table>", "<tr><th>controller</th>"
            + "".join(f"<th>{e(header)}</th>" for header, _, _ in BODY_COLUMNS) + "</tr>"]
    rows += [f"<tr><td>{e(spec)}</td>" + "".join(f"<td>{e(c)}</td>" for c in body_cells(m))
             + "</tr>" for spec, m in document["controllers"].items()]
    first = next(iter(document["controllers"].values()))
    ports = list(first.get("ports", {}))
    if ports:
        rows += ["</table>", "<table>", "<tr><th>controller</th>"
                 + "".join(f"<th>{e(p)}: force max / RMS (N), displacement max (um)</th>"
                           for p in ports) + "</tr>"]
        for spec, m in document["controllers"].items():
            cells = [f"{m['ports'][p]['force_max_n']:.3f} / {m['ports'][p]['force_rms_n']:.3f}, "
                     f"{1e6 * m['ports'][p]['displacement_max_m']:.3g}"
                     if p in m["ports"] else "-" for p in ports]
            rows.append(f"<tr><td>{e(spec)}</td>" + "".join(f"<td>{e(c)}</td>" for c in cells)
                        + "</tr>")
    rows.append("</table>")
    return "\n".join(rows)


def _collision_table(document: dict) -> str:
    """Per controller: the minimum distance, penetrations, safety violations, contacts
    (design 18.6), beside the hole and EE errors, and the closest pair."""
    e = html.escape
    rows = ["<table>", "<tr><th>controller</th>"
            + "".join(f"<th>{e(header)}</th>" for header, _, _ in COLLISION_COLUMNS)
            + "<th>closest pair</th></tr>"]
    for spec, m in document["controllers"].items():
        cells = ["-" if m.get(key) is None else fmt(m[key]) for _, key, fmt in COLLISION_COLUMNS]
        cells.append(m.get("closest_pair") or "-")
        rows.append(f"<tr><td>{e(spec)}</td>" + "".join(f"<td>{e(c)}</td>" for c in cells)
                    + "</tr>")
    rows.append("</table>")
    return "\n".join(rows)


def _parts_table(document: dict) -> str:
    """Per controller: each EE's position / orientation error, each constraint's error."""
    e = html.escape
    first = next(iter(document["controllers"].values()))
    frames, names = list(first["end_effectors"]), list(first["constraints"])
    headers = ([f"{frame} pos RMS / max (mm)" for frame in frames]
               + [f"{frame} ori RMS (mrad)" for frame in frames]
               + [f"{name} max (m)" for name in names])
    rows = ["<table>", "<tr><th>controller</th>"
            + "".join(f"<th>{e(header)}</th>" for header in headers) + "</tr>"]
    for spec, m in document["controllers"].items():
        ees, constraints = m["end_effectors"], m["constraints"]
        cells = ([f"{1e3 * ees[f]['position_error_rms_m']:.3f} / "
                  f"{1e3 * ees[f]['position_error_max_m']:.3f}" for f in frames]
                 + [f"{1e3 * ees[f]['orientation_error_rms_rad']:.3f}" for f in frames]
                 + [f"{constraints[n]['error_max_m']:.1e}" if n in constraints else "-"
                    for n in names])
        rows.append(f"<tr><td>{e(spec)}</td>" + "".join(f"<td>{e(c)}</td>" for c in cells) + "</tr>")
    rows.append("</table>")
    return "\n".join(rows)


def _status_table(document: dict) -> str:
    e = html.escape
    statuses = ("ok", "scaled", "least_squares", "constraint_degraded", "failed")
    rows = ["<table>", "<tr><th>controller</th>"
            + "".join(f"<th>{status}</th>" for status in statuses)
            + "<th>first failure</th></tr>"]
    for spec, metrics in document["controllers"].items():
        counts = metrics["status_counts"]
        rows.append(f"<tr><td>{e(spec)}</td>"
                    + "".join(f"<td>{counts.get(status, 0)}</td>" for status in statuses)
                    + f"<td>{e(metrics['first_failure'] or '-')}</td></tr>")
    rows.append("</table>")
    summary = "; ".join(f"{spec}: {format_status_counts(m['status_counts'])}"
                        for spec, m in document["controllers"].items())
    own = "; ".join(f"{spec}: {format_status_counts(m['controller_status_counts'])}"
                    for spec, m in document["controllers"].items()
                    if "controller_status_counts" in m)
    note = ("The loop's status: the controller's, or constraint_degraded where the supervisor "
            "measured a constraint error or port force beyond tolerance at the sensed "
            f"configuration (design 5.2). {summary}."
            + (f" The controllers' own step status: {own}." if own else ""))
    return "\n".join(rows) + f'\n<p class="note">{e(note)}</p>'


def _supervisor_table(document: dict) -> str:
    """What the supervisor measured and did, per controller, and its thresholds (design
    5.2); a line saying so for a document written before it existed."""
    e = html.escape
    config = document.get("supervisor")
    if config is None:
        return "<p>Not recorded (metrics written before the supervisor).</p>"
    rows = ["<table>", "<tr><th>controller</th><th>measured error max (mm)</th>"
            "<th>measured port force max (N)</th><th>scaled steps</th><th>held steps</th>"
            "<th>smallest scale</th><th>first action</th></tr>"]
    for spec, metrics in document["controllers"].items():
        m = metrics["supervisor"]
        force = m["measured_port_force_max_n"]
        cells = [f"{1e3 * m['measured_error_max_m']:.3f}",
                 "-" if force is None else f"{force:.3f}", str(m["scaled_steps"]),
                 str(m["held_steps"]), f"{m['scale_min']:.2f}"]
        rows.append(f"<tr><td>{e(spec)}</td>" + "".join(f"<td>{c}</td>" for c in cells)
                    + f'<td style="text-align:left">{e(m["first_action"] or "-")}</td></tr>')
    rows.append("</table>")
    note = (f"Measured every period at the sensed configuration (encoder noise included) and, "
            f"on the physics plant, the port force: ok up to {1e3 * config['tolerance_m']:g} mm "
            f"and {config['force_tolerance_n']:g} N; "
            + ("the operator's motion scaled from 1 at "
               f"{1e3 * config['error_warn_m']:g} mm ({config['force_warn_n']:g} N) to 0 at "
               f"{1e3 * config['error_hold_m']:g} mm ({config['force_hold_n']:g} N), where the "
               f"target is held; the scale down in no less than "
               f"{config.get('fall_time_s', 0.0):g} s, back up in no less than "
               f"{config['release_time_s']:g} s; the offset left is kept (a clutch)."
               if config["acting"] else "measuring only: it never scaled nor held."))
    return "\n".join(rows) + f'\n<p class="note">{e(note)}</p>'


def _failures(document: dict) -> list[str]:
    """The failed steps of every controller, counted by message (the loop's stop each
    time: the command nearest zero), or nothing when none failed."""
    e = html.escape
    lines = [(spec, entry)
             for spec, m in document["controllers"].items() for entry in m.get("failures", [])]
    if not lines:
        return []
    rows = ['<p class="note">Failed steps: no command could be computed, the robot was '
            "given the stop (the command nearest zero). Every failed step is counted.</p>",
            "<table>", "<tr><th>controller</th><th>failed steps</th><th>first (step, t)</th>"
            "<th>message</th></tr>"]
    rows += [f"<tr><td>{e(spec)}</td><td>{entry['count']}</td>"
             f"<td>{entry['first_step']}, {entry['first_t_s']:.3f} s</td>"
             f'<td style="text-align:left">{e(entry["message"])}</td></tr>'
             for spec, entry in lines]
    rows.append("</table>")
    return rows


def _solver_messages(document: dict) -> str:
    e = html.escape
    failures = _failures(document)
    lines = [(spec, message, count) for spec, m in document["controllers"].items()
             for message, count in m["solver_messages"].items()]
    if not lines:
        return "\n".join(failures or [
            "<p>Nothing: no step failed, and no solver printed or warned during the runs.</p>"])
    rows = [*failures, ('<p class="note">Kept off the console during the runs (design 15.5): each '
             "distinct line with the number of times it came.</p>"), "<table>",
            "<tr><th>controller</th><th>times</th><th>message</th></tr>"]
    rows += [f"<tr><td>{e(spec)}</td><td>{count}</td>"
             f'<td style="text-align:left">{e(message)}</td></tr>'
             for spec, message, count in lines]
    rows.append("</table>")
    return "\n".join(rows)
