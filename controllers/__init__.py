"""Controllers: EE body twist in, joint velocities out, constraints held.

* :class:`CJMController` - the paper's Constrained Jacobian Matrix (analytical + general).
* :class:`QPController` - the same rows as hard equalities in a QP (qpsolvers backends).
"""

from .base import Controller, SolveInfo, SolverError
from .cjm import CJMController
from .linalg import DampingPolicy, damped_least_squares, nullspace
from .qp import QPController

__all__ = [
    "CJMController",
    "Controller",
    "DampingPolicy",
    "QPController",
    "SolveInfo",
    "SolverError",
    "damped_least_squares",
    "nullspace",
]
