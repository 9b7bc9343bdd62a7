"""Controllers: EE body twist in, joint velocities out, constraints held.

* :class:`CJMController` - the paper's Constrained Jacobian Matrix (analytical + general).
* :class:`QPController` - the same rows as hard equalities in a QP (qpsolvers backends).
* :class:`MinkController` - the same task through mink on a MuJoCo model (the outside
  peer); imported on first use, since MuJoCo takes a while to load.
"""

from .base import Controller, SolveInfo, SolverError, StepStatus
from .cjm import CJMController
from .joint_limits import JointBounds
from .linalg import DampingPolicy, damped_least_squares, nullspace
from .qp import QPController

__all__ = [
    "CJMController",
    "Controller",
    "DampingPolicy",
    "JointBounds",
    "MinkController",
    "QPController",
    "SolveInfo",
    "SolverError",
    "StepStatus",
    "damped_least_squares",
    "nullspace",
]


def __getattr__(name: str):
    if name == "MinkController":
        from .mink import MinkController

        return MinkController
    raise AttributeError(f"module 'controllers' has no attribute {name!r}")
