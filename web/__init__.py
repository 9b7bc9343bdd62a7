"""Browser teleoperation UI (viser) over the teleop core: ``teleop web`` / ``python -m web``."""

from .app import ControlThread, TeleopApp

__all__ = ["ControlThread", "TeleopApp"]
