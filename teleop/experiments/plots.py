"""PNG plots of a comparison: the paper's Figs 3-4, constraint error and step time."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .plan import Plan
    from .results import RunResult


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    return plt


def write_plots(plan: "Plan", results: dict[str, "RunResult"], out: Path) -> list[Path]:
    """Write the four plots into ``out`` and return their paths."""
    plt = _pyplot()
    paths = []
    title = f"{plan.name} ({plan.robot.name})"

    # Fig 3: velocity of the constrained point across the constraint directions
    width = max(r.constraint_velocity.shape[1] for r in results.values())
    if width:
        fig, axes = plt.subplots(width, 1, figsize=(9, 2.4 * width + 0.8), sharex=True,
                                 squeeze=False)
        for spec, r in results.items():
            for j in range(r.constraint_velocity.shape[1]):
                axes[j, 0].plot(r.columns["t"], r.constraint_velocity[:, j], label=spec, lw=1)
        for j in range(width):
            axes[j, 0].set_ylabel(f"C v_c [{j}] (m/s)")
            axes[j, 0].grid(alpha=0.3)
        axes[0, 0].set_title(f"Velocity at the constraint point across the constraint ({title})")
        axes[0, 0].legend(fontsize=8, ncol=3)
        axes[-1, 0].set_xlabel("time (s)")
        paths.append(_save(fig, out / "constraint_velocity.png", plt))

    # Fig 4: desired vs actual EE linear velocity
    fig, axes = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True)
    first = next(iter(results.values()))
    for j, axis in enumerate("xyz"):
        axes[j].plot(first.columns["t"], first.desired_linear_velocity[:, j], "k--", lw=2,
                     label="desired")
        for spec, r in results.items():
            axes[j].plot(r.columns["t"], r.actual_linear_velocity[:, j], lw=1, label=spec)
        axes[j].set_ylabel(f"v_{axis} (m/s)")
        axes[j].grid(alpha=0.3)
    axes[0].set_title(f"End-effector linear velocity, world frame ({title})")
    axes[0].legend(fontsize=8, ncol=3)
    axes[-1].set_xlabel("time (s)")
    paths.append(_save(fig, out / "ee_velocity.png", plt))

    # constraint error (log scale) and barrier penetration
    fig, ax = plt.subplots(figsize=(9, 4))
    for spec, r in results.items():
        error = np.maximum(r.columns["constraint_error"], r.columns["barrier_penetration"])
        ax.semilogy(r.columns["t"], np.maximum(error, 1e-16), lw=1, label=spec)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("constraint error (m)")
    ax.set_title(f"Constraint error: hole offset / plane distance / penetration ({title})")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, ncol=3)
    paths.append(_save(fig, out / "constraint_error.png", plt))

    # step time distribution
    fig, ax = plt.subplots(figsize=(9, 4))
    specs = list(results)
    ax.boxplot([results[s].columns["step_time_us"] for s in specs], showfliers=False)
    ax.set_xticks(range(1, len(specs) + 1), specs, rotation=15)
    ax.set_yscale("log")
    ax.set_ylabel("controller step time (us)")
    ax.set_title(f"Controller step time, whiskers 1.5 IQR ({title})")
    ax.grid(alpha=0.3, which="both", axis="y")
    paths.append(_save(fig, out / "step_time.png", plt))
    return paths


def _save(fig, path: Path, plt) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
