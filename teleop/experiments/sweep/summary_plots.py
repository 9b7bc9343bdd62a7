"""The box plots of a sweep's summary: one figure per metric, one box per controller over
its done cells, every cell drawn as a dot beside its box (docs/sweep.md)."""

from __future__ import annotations

import io
from typing import Mapping, Sequence

import numpy as np

#: A metric's axis is logarithmic when its positive values span this ratio (two decades).
LOG_SPAN = 100.0

#: Dots are drawn over a box (each cell) up to this many cells per controller.
MAX_DOTS = 500


def axis_scale(values: Sequence[float] | np.ndarray) -> tuple[str, float | None]:
    """The y scale for ``values``: ``("log", None)`` when the positive ones span
    :data:`LOG_SPAN` or more and none is 0, ``("symlog", t)`` when they span it with zeros
    among them (linear below the smallest positive value ``t``), else ``("linear", None)``."""
    data = np.asarray(values, dtype=float)
    positive = data[data > 0]
    if positive.size < 2 or positive.max() < LOG_SPAN * positive.min():
        return "linear", None
    if positive.size == data.size:
        return "log", None
    return "symlog", float(positive.min())


def box_plot(values: Mapping[str, Sequence[float]], title: str, axis_label: str,
             integer: bool = False) -> bytes:
    """A PNG (its bytes) of one box per controller of ``values`` (controller -> its cells'
    values, in the order given; a controller without a value is left out), the cells as
    dots, on the scale of :func:`axis_scale`; ``integer``: counts, whole ticks only."""
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    shown = {name: np.asarray(data, dtype=float) for name, data in values.items() if len(data)}
    if not shown:
        raise ValueError(f"{title}: no controller has a value to plot")
    names = list(shown)
    width = max(6.0, 1.4 * len(names) + 2.0)
    fig, ax = plt.subplots(figsize=(width, 4.2))
    positions = np.arange(1, len(names) + 1)
    ax.boxplot([shown[name] for name in names], positions=positions, widths=0.5,
               showfliers=False, medianprops={"color": "tab:red", "linewidth": 1.5})
    spread = np.random.default_rng(0)  # the same dots on every summary of the same rows
    for position, name in zip(positions, names):
        data = shown[name][:MAX_DOTS]
        offsets = spread.uniform(-0.15, 0.15, data.size) if data.size > 1 else np.zeros(1)
        ax.plot(position + 0.35 + offsets * 0.5, data, "o", color="tab:blue", alpha=0.5,
                markersize=3.5)
    ax.set_xticks(positions, [f"{name}\n({_cells(shown[name].size)})" for name in names])
    if len(names) > 5:
        ax.tick_params(axis="x", labelrotation=30)
    every = np.concatenate(list(shown.values()))
    scale, threshold = axis_scale(every)
    if scale == "symlog":  # the values are >= 0: no negative decades, a decade above
        ax.set_yscale("symlog", linthresh=threshold)
        ax.set_ylim(-0.05 * threshold, 2.0 * float(every.max()))
    elif scale == "log":
        ax.set_yscale("log")
    elif integer:
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylim(-0.5, max(1.0, float(every.max())) * 1.1 + 0.5)  # counts: none below 0
    ax.set_ylabel(axis_label)
    ax.set_title(title)
    ax.grid(True, axis="y", which="major", alpha=0.3)
    fig.tight_layout()
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100)
    plt.close(fig)
    return buffer.getvalue()


def _cells(count: int) -> str:
    return f"{count} cell" if count == 1 else f"{count} cells"
