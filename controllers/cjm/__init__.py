"""The Constrained Jacobian Matrix controller (the paper's method, sections 4-7).

* :mod:`.controller` - :class:`CJMController`: options, step setup, backend;
* :mod:`.step_setup` - :class:`~.step_setup.StepSetup`, what a step is built from;
* :mod:`.python_step` - the step in Python (the readable reference);
* :mod:`.compiled` - the step in C++ (``_step/``), a thin wrapper;
* :mod:`.report` - the step's report and the one function that words it;
* :mod:`.tolerances` - every tolerance a step decides with;
* :mod:`.analytical` - the paper's analytical form (square and redundant pre-chains);
* :mod:`.general` - the general null-space form over stacked rows;
* :mod:`.saturation` - joint limits by saturation in the null space.
"""

from .controller import CJMController

__all__ = ["CJMController"]
