"""The browser session's core, without any browser (:class:`TeleopApp`), and the thread
that runs it (:class:`ControlThread`); one module per concern (:mod:`web.app.core`)."""

from .control_thread import SWITCH_INTERVAL, TIMING_WINDOW, ControlThread, Timing
from .core import TeleopApp
from .editing import ConstraintEntry
from .limits import (
    HISTORY_RATE,
    HISTORY_SECONDS,
    MAX_DAMPING,
    MAX_GHOST_OFFSET,
    MAX_MOTION_SCALE,
    MAX_RATE,
    MAX_TARGET_DISTANCE,
    MIN_RATE,
)
from .plant import PortReading
from .robots import default_ghost_offset
from .status import (BEHIND_FRACTION, Limitation, behind_words, describe_limitation, port_words,
                     summary_words, supervision_words)

__all__ = [
    "BEHIND_FRACTION",
    "ConstraintEntry",
    "ControlThread",
    "HISTORY_RATE",
    "HISTORY_SECONDS",
    "Limitation",
    "MAX_DAMPING",
    "MAX_GHOST_OFFSET",
    "MAX_MOTION_SCALE",
    "MAX_RATE",
    "MAX_TARGET_DISTANCE",
    "MIN_RATE",
    "PortReading",
    "SWITCH_INTERVAL",
    "TIMING_WINDOW",
    "TeleopApp",
    "Timing",
    "behind_words",
    "default_ghost_offset",
    "describe_limitation",
    "port_words",
    "summary_words",
    "supervision_words",
]
