"""The live plots (uPlot): the last seconds of each robot's measures, in units that keep
the numbers readable (docs/design.md section 5.3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import viser
import viser.uplot as uplot

from ..app import HISTORY_SECONDS

MAIN_COLOR = "#d97706"
GHOST_COLOR = "#2563eb"
GHOST_DASH = (6.0, 4.0)  # the ghost's plot lines are dashed: the main one shows where they agree

#: display units per quantity: (name, size in SI units), largest first
UNITS = {"m": (("m", 1.0), ("mm", 1e-3), ("µm", 1e-6), ("nm", 1e-9)),
         "m/s": (("m/s", 1.0), ("mm/s", 1e-3), ("µm/s", 1e-6), ("nm/s", 1e-9)),
         "us": (("µs", 1.0),),
         "rad/s": (("rad/s", 1.0), ("mrad/s", 1e-3), ("µrad/s", 1e-6), ("nrad/s", 1e-9)),
         "N": (("N", 1.0), ("mN", 1e-3), ("µN", 1e-6), ("nN", 1e-9))}


def display_unit(values: np.ndarray, quantity: str, current: str | None = None) -> tuple[str, float]:
    """The unit that shows ``values`` as readable numbers (the largest with a peak >= 1),
    kept while the peak stays within [0.5, 2000) of ``current`` (no flicker)."""
    units = UNITS[quantity]
    finite = values[np.isfinite(values)]
    peak = float(np.max(np.abs(finite))) if finite.size else 0.0
    sizes = dict(units)
    if current in sizes and 0.5 <= peak / sizes[current] < 2000.0:
        return current, sizes[current]
    for name, size in units:
        if peak >= size:
            return name, size
    return units[-1]


@dataclass(frozen=True)
class PlotSpec:
    key: str  # a Trace column
    title: str
    quantity: str  # a key of UNITS
    ghost_only: bool = False


PLOTS = (PlotSpec("constraint_error", "constraint error", "m"),
         PlotSpec("constraint_velocity", "constraint velocity |C v_c|", "m/s"),
         PlotSpec("ee_error", "EE position error", "m"),
         PlotSpec("step_time", "controller step time", "us"),
         PlotSpec("qd_deviation", "joint-velocity deviation |qd_ghost - qd_main|", "rad/s",
                  ghost_only=True))
#: the plots of a session on a physics plant, after :data:`PLOTS`
PLANT_PLOTS = (PlotSpec("port_force", "port force, the largest", "N"),)


#: the plots of a session whose controllers avoid collisions, after the others
COLLISION_PLOTS = (PlotSpec("minimum_distance",
                            "minimum distance, closest collision pair (shown up to d_i)", "m"),)


def plots_of(snapshot: dict) -> tuple[PlotSpec, ...]:
    """The plots of the session ``snapshot`` shows: :data:`PLOTS`, on a physics plant
    :data:`PLANT_PLOTS`, with collision pairs to check :data:`COLLISION_PLOTS`."""
    plots = PLOTS + PLANT_PLOTS if snapshot["plant"].physical else PLOTS
    return plots + COLLISION_PLOTS if snapshot["collisions"]["checking"] else plots


#: x: the last 10 s, "now" at 0. A fixed range: an auto-ranged x axis of a plot updated
#: while its tab is hidden keeps a stale range in viser's client (the lines fall outside)
X_RANGE = (-HISTORY_SECONDS, 0.0)
#: y from 0 (the measures are norms), at least up to 1 display unit: an all-zero trace
#: reads "0 ... 1 nm", not uPlot's default 0-100
Y_RANGE = {"min": {"pad": 0.0, "soft": 0.0, "mode": 1}, "max": {"pad": 0.1, "soft": 1.0, "mode": 1}}


def axes_labelled(unit: str) -> tuple[uplot.Axis, uplot.Axis]:
    """The x axis labelled in seconds before now, the y axis in ``unit``, each with room
    for its tick values (the default clips five-digit values on a narrow panel)."""
    return (uplot.Axis(label="t - now (s)", labelSize=18.0, size=36.0),
            uplot.Axis(label=unit, labelSize=18.0, size=56.0))


def plot_series(snapshot: dict, spec: PlotSpec) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Time and the series of one plot, all finite and of one length: with a ghost, the
    samples since it joined (both robots measured at the same ticks)."""
    robots = snapshot["robots"]
    traces = {which: robot["trace"] for which, robot in robots.items()}
    shown = ["ghost"] if spec.ghost_only else list(traces)
    if spec.ghost_only and "ghost" not in traces:
        return np.zeros(0), {}
    n = min(traces[which]["t"].size for which in traces)
    t = traces["main"]["t"][-n:] if n else np.zeros(0)
    series = {which: traces[which][spec.key][-n:] for which in shown} if n else {}
    return t, series


class LivePlots:
    """The live plots of :class:`web.ui.TeleopUI`, a component owning its uPlot handles
    (:attr:`handles`, by measure) and the unit and series each shows; the view thread
    calls :meth:`draw`.

    Parameters
    ----------
    server : the viser server the plots are added to.
    tab : the "Plots" tab they go in.
    """

    def __init__(self, server: viser.ViserServer, tab: viser.GuiTabHandle) -> None:
        self.server = server
        self.tab = tab
        self.handles: dict[str, viser.GuiUplotHandle] = {}
        self._keys: dict[str, tuple] = {}  # measure -> (unit, series labels) shown
        #: the robots the plots show
        self.plotted: set[str] = set()
        #: the main robot's largest port force over the plots' window (N; None: no port)
        self.port_peak: float | None = None

    def draw(self, snapshot: dict) -> None:
        """The plots of the session ``snapshot`` (:func:`plots_of`), each on its last
        seconds; a plot whose unit or series changed is replaced."""
        robots = snapshot["robots"]
        shown: set[str] = set()
        for spec in plots_of(snapshot):
            t, series = plot_series(snapshot, spec)
            if t.size < 2:
                if spec.ghost_only and spec.key in self.handles and "ghost" not in robots:
                    self.handles.pop(spec.key).remove()
                    self._keys.pop(spec.key, None)
                continue
            values = np.concatenate(list(series.values()))
            current = self._keys.get(spec.key, (None,))[0]
            unit, size = display_unit(values, spec.quantity, current)
            labels = tuple(f"{which} ({robots[which]['spec']})" for which in series)
            key = (unit, labels)
            data = (t - snapshot["robots"]["main"]["t"],  # seconds before now: a fixed x axis
                    *[column / size for column in series.values()])
            if self._keys.get(spec.key) != key:
                self._replace(spec, unit, series, labels, data)
                self._keys[spec.key] = key
            else:
                self.handles[spec.key].data = data
            shown.update(series)
        self.plotted = shown
        trace = robots["main"]["trace"]
        forces = trace["port_force"][np.isfinite(trace["port_force"])]
        self.port_peak = float(forces.max()) if forces.size else None

    def _replace(self, spec: PlotSpec, unit: str, series: dict, labels: tuple,
                 data: tuple) -> None:
        """A new uPlot for a new unit or set of series, where the old one was."""
        old = self.handles.pop(spec.key, None)
        order = old.order if old is not None else None
        if old is not None:
            old.remove()
        colors = {"main": MAIN_COLOR, "ghost": GHOST_COLOR}
        with self.tab:
            self.handles[spec.key] = self.server.gui.add_uplot(
                data=data,
                series=(uplot.Series(label="t - now (s)"),
                        *[uplot.Series(label=label, stroke=colors[which], width=1.5,
                                       **({} if which == "main" else {"dash": GHOST_DASH}))
                          for which, label in zip(series, labels)]),
                title=f"{spec.title} ({unit})", aspect=2.0, order=order,
                scales={"x": uplot.Scale(time=False, auto=False, range=X_RANGE),
                        "y": uplot.Scale(auto=True, range=Y_RANGE)},
                axes=axes_labelled(unit))
