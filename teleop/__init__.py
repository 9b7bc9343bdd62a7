"""Constrained operational-space teleoperation (CJM, QP baseline, browser UI)."""

from .robot import BUILTIN_ROBOTS, Robot, load_robot

__all__ = ["Robot", "load_robot", "BUILTIN_ROBOTS"]
