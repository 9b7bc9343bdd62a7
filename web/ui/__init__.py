"""The viser front end over :class:`web.app.TeleopApp` (:class:`TeleopUI`) and the server
that runs both (:func:`run_server`); one module per part (:mod:`web.ui.core`)."""

from .core import TeleopUI
from .teleop_panel import CONTROLLER_CHOICES, NUDGES
from .collision_view import distance_color
from .placed_markers import node_name
from .plots import (
    COLLISION_PLOTS,
    GHOST_COLOR,
    MAIN_COLOR,
    PLANT_PLOTS,
    PLOTS,
    PlotSpec,
    display_unit,
    plot_series,
    plots_of,
)
from .port_forces import FORCE_ARROW_PER_DECADE, arrow_length, force_arrow
from .scene_view import STATUS_COLORS
from .server import run_server
from .shapes import LinkProfile, reach_from_axis

__all__ = [
    "COLLISION_PLOTS",
    "FORCE_ARROW_PER_DECADE",
    "CONTROLLER_CHOICES",
    "GHOST_COLOR",
    "LinkProfile",
    "MAIN_COLOR",
    "NUDGES",
    "PLANT_PLOTS",
    "PLOTS",
    "PlotSpec",
    "STATUS_COLORS",
    "TeleopUI",
    "display_unit",
    "distance_color",
    "node_name",
    "reach_from_axis",
    "plot_series",
    "plots_of",
    "arrow_length",
    "force_arrow",
    "run_server",
]
