"""The Constrained Jacobian Matrix controller (the paper's method, sections 4-7).

* :mod:`.controller` - :class:`CJMController`: which form solves a step, barriers, limits;
* :mod:`.analytical` - the paper's analytical form (square and redundant pre-chains);
* :mod:`.general` - the general null-space form over stacked rows;
* :mod:`.saturation` - joint limits by saturation in the null space.
"""

from .controller import CJMController

__all__ = ["CJMController"]
