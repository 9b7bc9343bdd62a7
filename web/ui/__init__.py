"""The viser front end over :class:`web.app.TeleopApp` (:class:`TeleopUI`) and the server
that runs both (:func:`run_server`); one module per part (:mod:`web.ui.core`)."""

from .core import TeleopUI
from .panels import CONTROLLER_CHOICES, NUDGES
from .plots import GHOST_COLOR, MAIN_COLOR, PLOTS, PlotSpec, display_unit, plot_series
from .scene_view import STATUS_COLORS
from .server import run_server
from .shapes import LinkProfile, reach_from_axis

__all__ = [
    "CONTROLLER_CHOICES",
    "GHOST_COLOR",
    "LinkProfile",
    "MAIN_COLOR",
    "NUDGES",
    "PLOTS",
    "PlotSpec",
    "STATUS_COLORS",
    "TeleopUI",
    "display_unit",
    "reach_from_axis",
    "plot_series",
    "run_server",
]
