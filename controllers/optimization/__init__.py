"""What the two optimiser controllers share (the QP controller and the mink peer).

* :mod:`.problem` - the quadratic program handed to a backend and its answer;
* :mod:`.proxqp` - proxqp as persistent ``proxsuite`` objects;
* :mod:`.budget` - a step's iteration caps and deadline (docs/design.md 10.6);
* :mod:`.least_residual` - the rows held at their least residual when they conflict with
  the limits (docs/design.md 10.7);
* :mod:`.task_damping` - the CJM's damping as rows of an optimiser's task (10.7).
"""
