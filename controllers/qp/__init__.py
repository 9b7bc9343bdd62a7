"""The QP controller: the CJM's priorities as quadratic programs (docs/design.md 4.7, 10).

* :mod:`.controller` - :class:`QPController`, the step;
* :mod:`.assembly` - the normalised task objective ``M^T M``, ``-M^T m``;
* :mod:`.geometry` - ``null(M)`` and the task's curvature (Cholesky or SVD);
* :mod:`.posture_stage` - stage 2 of the lexicographic solve, and the polish on the face;
* :mod:`.daqp_direct`, :mod:`.qpsolvers_path` - the backends not shared with the mink peer
  (proxqp's persistent objects are in :mod:`controllers.optimization.proxqp`).
"""

from ..numerics import SOLVER_SETTINGS
from .controller import DEFAULT_POSTURE_WEIGHT, Priorities, QPController

__all__ = ["DEFAULT_POSTURE_WEIGHT", "SOLVER_SETTINGS", "Priorities", "QPController"]
