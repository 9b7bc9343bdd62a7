"""PNG plots of a comparison (docs/design.md sections 15.2 and 17.3): the paper's Figs 3-4,
the constraint error, the port force (on a plant with a body), the joint-velocity
agreement and the step time. The figures are drawn from the runs on the comparison's plant
and their titles name it.

Controllers whose curves coincide are drawn once: :func:`overlap_groups` puts them in one
group, each figure says which controllers a curve stands for and how far apart they are at
most, and the paper's figures get one file per group.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

if TYPE_CHECKING:
    from .plan import Plan
    from teleop.plants.choice import PlantChoice
    from .results import RunResult

#: Curves coincide when they differ by at most this fraction of their largest |value|
#: (well under a line's width on the figures below).
OVERLAP_RTOL = 1e-3

#: An EE-velocity axis spans at least this fraction of the figure's largest velocity.
MIN_SPAN = 0.05

#: What a step status looks like behind the EE-velocity curves: colour and legend text.
STATUS_SHADING = {
    "scaled": ("tab:olive", "scaled: the task slowed to keep the joint limits"),
    "least_squares": ("tab:gray", ("least_squares: the task not fully achievable "
                                   "(a barrier, the constraints' lost DoF, a joint at a limit)")),
    "constraint_degraded": ("tab:red", "constraint_degraded: a constraint not held"),
    "failed": ("black", "failed: zero command"),
}


@dataclass(frozen=True)
class Figure:
    """One written plot: its file, a title, what it shows in a sentence or two, and the
    titles of its panels as drawn (read back from the axes)."""

    path: Path
    title: str
    caption: str
    panels: tuple[str, ...] = ()


@dataclass(frozen=True)
class Group:
    """Controllers whose curves coincide: ``members`` (the first one's curves are drawn) and
    the largest difference found between any member and the first (the curves' units)."""

    members: tuple[str, ...]
    difference: float

    @property
    def name(self) -> str:
        return ", ".join(self.members)

    def overlap(self, unit: str) -> str:
        """A sentence stating the overlap (empty for a single controller)."""
        if len(self.members) == 1:
            return ""
        return (f"One curve stands for {self.name}: they differ by at most "
                f"{self.difference:.1e} {unit}.")


def overlap_groups(series: dict[str, np.ndarray], rtol: float = OVERLAP_RTOL,
                   atol: float = 0.0) -> list[Group]:
    """Group the controllers, in order, whose ``series`` coincide: same shape, NaN in the
    same places, and ``max |a - b| <= rtol max |a| + atol`` against the group's first member
    (``atol``: a difference too small to mean anything, such as round-off)."""
    if not rtol >= 0:
        raise ValueError(f"rtol must be >= 0, got {rtol}")
    if not atol >= 0:
        raise ValueError(f"atol must be >= 0, got {atol}")
    groups: list[list] = []  # [first spec, members, largest difference]
    for spec, values in series.items():
        for group in groups:
            first = series[group[0]]
            if first.shape != values.shape or not np.array_equal(np.isnan(first), np.isnan(values)):
                continue
            finite = np.isfinite(first)
            difference = float(np.max(np.abs(first[finite] - values[finite]), initial=0.0))
            if difference <= rtol * float(np.max(np.abs(first[finite]), initial=0.0)) + atol:
                group[1].append(spec)
                group[2] = max(group[2], difference)
                break
        else:
            groups.append([spec, [spec], 0.0])
    return [Group(tuple(members), difference) for _, members, difference in groups]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    return plt


def _file(out: Path, stem: str, group: Group, first: bool) -> Path:
    """``stem.png`` for the group holding the first controller, ``stem_<member>.png`` else."""
    if first:
        return out / f"{stem}.png"
    return out / f"{stem}_{group.members[0].replace(':', '-')}.png"


def _positive(values: np.ndarray) -> np.ndarray:
    """``|values|`` with exact zeros as NaN (not drawn on a log axis)."""
    magnitude = np.abs(values)
    return np.where(magnitude > 0, magnitude, np.nan)


#: The lowest value a log axis of lengths (m) or joint velocities (rad/s) shows: the
#: measures' resolution (:data:`teleop.experiments.metrics_table.RESOLUTION`); below it a
#: value is rounding, not signal.
LOG_FLOOR = 1e-12


def log_floor(axis, floor: float) -> None:
    """``axis`` (log y) from ``floor`` up, at least a decade above it: what lies below the
    floor (rounding, down to 1e-30) is not drawn magnified."""
    low, high = axis.get_ylim()
    axis.set_ylim(floor, max(high, 10.0 * floor))


def _symmetric_limits(limits: tuple[float, float], span: float) -> tuple[float, float]:
    """``limits`` widened to at least ``[-span, span]``, so that a component staying at zero
    up to round-off is drawn flat rather than magnified to fill its axis."""
    low, high = limits
    return min(low, -span), max(high, span)


def _spans(t: np.ndarray, mask: np.ndarray) -> list[tuple[float, float]]:
    """Time intervals where ``mask`` holds (each step covers ``(t - dt, t]``)."""
    dt = float(t[1] - t[0]) if len(t) > 1 else 0.0
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    return [(t[start] - dt, t[end - 1]) for start, end in zip(edges[::2], edges[1::2])]


def write_plots(plan: "Plan", results: dict[str, "RunResult"], out: Path,
                plant: "PlantChoice | None" = None) -> list[Figure]:
    """Write every plot into ``out`` and return them (``plant``: the runs' plant, named in
    the titles; None: the kinematic one)."""
    plt = _pyplot()
    title = f"{plan.name} ({plan.robot.name}" + (
        f", {plant.kind} plant)" if plant is not None else ")")
    figures = _constraint_velocity(plt, results, out, title)
    figures += _ee_velocity(plt, results, out, title)
    figures.append(_constraint_error(plt, results, out, title))
    if any(r.port_forces for r in results.values()):
        figures.append(_port_force(plt, results, out, title))
    if any(r.safety_distance is not None for r in results.values()):
        figures.append(_minimum_distance(plt, results, out, title))
    if any(r.joint_velocity_deviation is not None for r in results.values()):
        figures.append(_agreement(plt, results, out, title))
    figures.append(_step_time(plt, results, out, title))
    return figures


def _constraint_velocity(plt, results: dict[str, "RunResult"], out: Path,
                         title: str) -> list[Figure]:
    """The paper's Fig 3: each equality row's velocity against the EE's speed, log axis,
    one file per group."""
    series = {spec: r.constraint_velocity for spec, r in results.items()}
    if not any(v.shape[1] for v in series.values()):
        return []
    floor = max(float(np.max(r.columns["constraint_velocity_floor"], initial=0.0))
                for r in results.values())  # below it, a difference is round-off
    # the axes stop a decade under the smallest round-off the runs measured
    positive = [float(np.min(f[f > 0])) for f in (r.columns["constraint_velocity_floor"]
                                                  for r in results.values()) if np.any(f > 0)]
    velocity_floor = 0.1 * min(positive) if positive else 1e-17
    figures = []
    for n, group in enumerate(overlap_groups(series, atol=floor)):
        r = results[group.members[0]]
        rows = r.constraint_velocity.shape[1]
        if not rows:
            continue
        t = r.columns["t"]
        fig, axes = plt.subplots(rows, 1, figsize=(12, 2.3 * rows + 1.2), sharex=True,
                                 squeeze=False, layout="constrained")
        speed = np.linalg.norm(r.actual_linear_velocity, axis=1)
        for j, label in enumerate(r.constraint_velocity_labels):
            axis = axes[j, 0]
            axis.semilogy(t, _positive(speed), color="black", lw=1.0,
                          label="EE speed, achieved |v_e|")
            axis.semilogy(t, _positive(r.drift_velocity[:, j]), color="tab:orange", lw=2.5,
                          alpha=0.5, label="drift correction K |e| at the true q (design 3.4)")
            axis.semilogy(t, _positive(r.constraint_velocity[:, j]), color="tab:blue", lw=0.7,
                          label="|C v_c| at the constraint, relative to its geometry")
            axis.semilogy(t, _positive(r.columns["constraint_velocity_floor"]), color="0.2",
                          lw=1.0, ls=":", zorder=5,
                          label="numerical floor: float64 round-off of C v_c and of K e")
            axis.set_title(label, fontsize=9, loc="left")
            axis.set_ylabel("m/s")
            log_floor(axis, velocity_floor)
            axis.grid(alpha=0.3, which="both")
        axes[-1, 0].set_xlabel("time (s)")
        handles, labels = axes[0, 0].get_legend_handles_labels()
        fig.legend(handles, labels, loc="outside lower center", ncols=2, fontsize=8)
        fig.suptitle(f"Velocity at the constraint vs the EE's speed ({title})\n{group.name}",
                     fontsize=10)
        panels = _panels(fig)
        path = _save(fig, _file(out, "constraint_velocity", group, n == 0), plt)
        caption = (f"{group.name}. Each constrained direction's velocity of the link point "
                   "relative to the constraint's geometry, on the same log axis as the EE's "
                   "speed. It equals the drift correction -K e the constraint asks for "
                   "(design 3.4) up to the command's residual; the dotted grey curve is the "
                   "float64 round-off of C v_c and of K e, below which a velocity is zero; "
                   "the axis starts a decade under its smallest value. "
                   "On a robot that is not perfect (design 15.1) the controller corrects the "
                   "error it measures, so the velocity departs from K |e| at the true q. "
                   + group.overlap("m/s"))
        figures.append(Figure(path, f"Velocity at the constraint: {group.name}", caption, panels))
    return figures


def _ee_velocity(plt, results: dict[str, "RunResult"], out: Path, title: str) -> list[Figure]:
    """The paper's Fig 4: the operator's target velocity, the commanded and the achieved EE
    linear velocity, with saturation and the step status shaded; one file per group."""
    series = {spec: np.hstack([r.commanded_linear_velocity, r.actual_linear_velocity,
                               r.columns["twist_saturated"][:, None]])
              for spec, r in results.items()}
    groups = overlap_groups(series)
    figures = []
    for n, group in enumerate(groups):
        r = results[group.members[0]]
        t = r.columns["t"]
        fig, axes = plt.subplots(3, 1, figsize=(12, 7.5), sharex=True, layout="constrained")
        shading = [(colour, text, r.statuses == status)
                   for status, (colour, text) in STATUS_SHADING.items()]
        span = MIN_SPAN * np.nanmax(np.abs(np.hstack([
            r.operator_linear_velocity, r.commanded_linear_velocity, r.actual_linear_velocity])),
            initial=0.0)
        for j, axis_name in enumerate("xyz"):
            axis = axes[j]
            for colour, text, mask in shading:
                for k, (start, end) in enumerate(_spans(t, mask)):
                    axis.axvspan(start, end, color=colour, alpha=0.15, lw=0,
                                 label=text if k == 0 else None)
            for k, (start, end) in enumerate(_spans(t, r.columns["twist_saturated"] > 0)):
                axis.axvspan(start, end, facecolor="none", edgecolor=(1.0, 0.5, 0.0, 0.4),
                             hatch="//", lw=0, label="speed cap: the commanded twist scaled down"
                             if k == 0 else None)
            axis.plot(t, r.actual_linear_velocity[:, j], color="tab:blue", lw=1.0,
                      label="achieved: J_e qd")
            axis.plot(t, r.commanded_linear_velocity[:, j], color="tab:red", lw=0.8,
                      label="commanded: K_p pose error + target feed-forward, capped")
            axis.plot(t, r.operator_linear_velocity[:, j], color="black", ls="--", lw=1.5,
                      label="operator's target velocity (filtered target)")
            axis.set_ylabel(f"v_{axis_name} (m/s)")
            axis.set_ylim(*_symmetric_limits(axis.get_ylim(), span))
            axis.grid(alpha=0.3)
        axes[-1].set_xlabel("time (s)")
        handles, labels = [], []
        for axis in axes:  # a shaded span may show on one axis only: gather every label once
            for handle, label in zip(*axis.get_legend_handles_labels()):
                if label not in labels:
                    handles.append(handle)
                    labels.append(label)
        fig.legend(handles, labels, loc="outside lower center", ncols=2, fontsize=8)
        fig.suptitle(f"End-effector linear velocity, world frame ({title})\n{group.name}",
                     fontsize=10)
        path = _save(fig, _file(out, "ee_velocity", group, n == 0), plt)
        differing = {spec: int(np.sum(results[spec].statuses != r.statuses))
                     for spec in group.members[1:]}
        shaded = "; ".join(f"{spec}'s status differs on {count} steps"
                           for spec, count in differing.items() if count)
        caption = (f"{group.name}. The operator's target velocity, the twist the loop "
                   "commanded (it also carries the pose-error term, so it grows while the "
                   "EE lags behind the target) and the EE velocity achieved. Hatched: steps "
                   "where the speed cap scaled the command; shaded: the step status when not "
                   f"ok ({group.members[0]}'s" + (f"; {shaded}" if shaded else "") + "). "
                   + group.overlap("m/s"))
        figures.append(Figure(path, f"EE velocity: {group.name}", caption))
    return figures


def _constraint_error(plt, results: dict[str, "RunResult"], out: Path, title: str) -> Figure:
    """Constraint error and barrier penetration, log axis, one curve per group."""
    series = {spec: np.maximum(r.columns["constraint_error"], r.columns["barrier_penetration"])
              for spec, r in results.items()}
    groups = overlap_groups(series)
    fig, ax = plt.subplots(figsize=(12, 4), layout="constrained")
    for group in groups:
        r = results[group.members[0]]
        ax.semilogy(r.columns["t"], _positive(series[group.members[0]]), lw=1, label=group.name)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("constraint error (m)")
    log_floor(ax, LOG_FLOOR)
    ax.grid(alpha=0.3, which="both")
    fig.legend(loc="outside right upper", fontsize=8)
    fig.suptitle(f"Constraint error: hole offset / plane distance / penetration ({title})",
                 fontsize=10)
    path = _save(fig, out / "constraint_error.png", plt)
    caption = ("The largest equality error (or barrier penetration) at the end of each step, "
               f"on the true configuration; the axis starts at {LOG_FLOOR:g} m, the measure's "
               "resolution. " + " ".join(g.overlap("m") for g in groups))
    return Figure(path, "Constraint error", caption.strip())


def _port_force(plt, results: dict[str, "RunResult"], out: Path, title: str) -> Figure:
    """The abdominal wall's force at each port over time, one curve per controller and
    port (N, linear axis)."""
    fig, ax = plt.subplots(figsize=(12, 4), layout="constrained")
    for spec, r in results.items():
        for name, force in r.port_force_magnitudes().items():
            ax.plot(r.columns["t"], force, lw=0.8,
                    label=spec if len(r.port_names) == 1 else f"{spec}: {name}")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("port force |F| (N)")
    ax.grid(alpha=0.3)
    fig.legend(loc="outside right upper", fontsize=8)
    fig.suptitle(f"Force of the abdominal wall on the instrument at each port ({title})",
                 fontsize=10)
    path = _save(fig, out / "port_force.png", plt)
    caption = ("The lateral spring-damper force of the tissue at each hole's port, "
               "|F| = |-k (P - c) - c_d v_perp| (design 17.2), at the last physics step of "
               "every control period, on the simulated robot.")
    return Figure(path, "Port force", caption)


def _minimum_distance(plt, results: dict[str, "RunResult"], out: Path, title: str) -> Figure:
    """The collision pairs' minimum distance over time, one curve per controller (mm),
    with the safety distance and the violation bound ``d_s - 0.5 mm``."""
    from teleop.loop import SAFETY_TOLERANCE

    fig, ax = plt.subplots(figsize=(12, 4), layout="constrained")
    safety = None
    for spec, r in results.items():
        if r.safety_distance is None:
            continue
        safety = r.safety_distance
        distance = r.columns["minimum_distance"]
        ax.plot(r.columns["t"], np.where(np.isfinite(distance), 1e3 * distance, np.nan),
                lw=1, label=spec)
    ax.axhline(1e3 * safety, color="k", lw=0.8, ls="--", label="safety distance d_s")
    ax.axhline(1e3 * (safety - SAFETY_TOLERANCE), color="r", lw=0.8, ls=":",
               label="d_s - 0.5 mm")
    ax.axhline(0.0, color="r", lw=0.8, label="contact")
    ax.set_xlim(0.0, max(float(r.columns["t"][-1]) for r in results.values()))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("minimum distance (mm)")
    ax.grid(alpha=0.3)
    fig.legend(loc="outside right upper", fontsize=8)
    fig.suptitle(f"Minimum distance between the collision pairs ({title})", fontsize=10)
    path = _save(fig, out / "minimum_distance.png", plt)
    caption = ("The smallest distance over the robot's self-collision and obstacle pairs at "
               "the end of each step, on the true configuration (design 18.6): exact below "
               "the detection distance; gaps where no pair came within the broadphase's reach.")
    return Figure(path, "Minimum distance", caption)


def _agreement(plt, results: dict[str, "RunResult"], out: Path, title: str) -> Figure:
    """``max_j |qd - qd_ref|`` per step of every controller against the reference."""
    reference = next(iter(results))
    fig, ax = plt.subplots(figsize=(12, 4), layout="constrained")
    for spec, r in list(results.items())[1:]:
        ax.semilogy(r.columns["t"], _positive(r.joint_velocity_deviation), lw=0.8, label=spec)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"max_j |qd_j - qd_{reference},j| (rad/s)")
    log_floor(ax, LOG_FLOOR)
    ax.grid(alpha=0.3, which="both")
    fig.legend(loc="outside right upper", fontsize=8)
    fig.suptitle(f"Joint-velocity agreement with {reference} at the same q and twist ({title})",
                 fontsize=10)
    path = _save(fig, out / "joint_velocity_agreement.png", plt)
    caption = (f"Along {reference}'s closed-loop run, every other controller solves at the "
               f"same configuration and twist (a shadow evaluation, design 15.3); the curve "
               f"is the largest joint-velocity difference from {reference}'s command. Exact "
               f"zeros are not drawn, and the axis starts at {LOG_FLOOR:g} rad/s, the "
               "measure's resolution.")
    return Figure(path, f"Joint-velocity agreement with {reference}", caption)


def _step_time(plt, results: dict[str, "RunResult"], out: Path, title: str) -> Figure:
    """The controller step time's distribution, per controller."""
    fig, ax = plt.subplots(figsize=(12, 4), layout="constrained")
    specs: Sequence[str] = list(results)
    ax.boxplot([results[s].columns["step_time_us"] for s in specs], showfliers=False)
    ax.set_xticks(range(1, len(specs) + 1), specs, rotation=15)
    ax.set_yscale("log")
    ax.set_ylabel("controller step time (us)")
    ax.grid(alpha=0.3, which="both", axis="y")
    fig.suptitle(f"Controller step time, whiskers 1.5 IQR ({title})", fontsize=10)
    path = _save(fig, out / "step_time.png", plt)
    return Figure(path, "Controller step time",
                  "controller.solve alone, per controller (boxes: quartiles; whiskers: 1.5 "
                  "IQR; outliers not drawn).")


def _panels(fig) -> tuple[str, ...]:
    """The title of every axis of ``fig`` (left-aligned titles), in order."""
    return tuple(axis.get_title(loc="left") for axis in fig.axes)


def _save(fig, path: Path, plt) -> Path:
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
