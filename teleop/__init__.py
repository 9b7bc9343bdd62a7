"""Constrained operational-space teleoperation: robots, the closed loop, experiments, CLI.

Subpackages: ``robots`` (models), ``loop`` (the closed teleoperation loop),
``experiments`` (scenarios, sessions, compare, metrics, plots, bench), ``cli``.
"""

from .robots import BUILTIN_ROBOTS, Robot, load_robot

__all__ = ["BUILTIN_ROBOTS", "Robot", "load_robot"]
