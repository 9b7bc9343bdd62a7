"""The outside peer: the same constrained teleoperation step posed to mink (docs/design.md 4.8).

mink (differential IK on a MuJoCo model) is what a user would pick instead of writing a
controller. :class:`MinkController` poses *the same* problem as
:class:`controllers.QPController` to it, so the three controllers can be compared step
for step on the same robot, constraints and operator command.

Conventions of mink 1.3.0 (read from ``mink/solve_ik.py``, ``mink/tasks/task.py``,
``mink/tasks/frame_task.py``, ``mink/limits/*.py``), on which everything below rests:

* The QP variable is the tangent displacement ``dq = v dt`` (MuJoCo dof order), not the
  velocity; ``solve_ik`` returns ``v = dq / dt``, the velocity with which
  ``configuration.integrate(v, dt)`` moves.
* A task with error ``e(q)`` and Jacobian ``J = de/dq`` is a cost
  ``|cost * (J dq + gain e)|^2``; in ``constraints=[task]`` it is the hard equality
  ``J dq = -gain e`` (``gain`` must lie in [0, 1]).
* ``FrameTask``: ``e = log(T_b^-1 T_t)`` (a body twist, ``LOCAL``, linear first: the
  right-minus ``T_t (-) T_b``) and ``J = -Jlog(T_t^-1 T_b) J_b`` with ``J_b`` the body
  Jacobian of the frame (see :class:`MinkController` for why this tracks ``V`` exactly).
* A limit returns ``G dq <= h`` at step ``dt``. mink's own ``VelocityLimit``
  (``|dq| <= v_max dt``) and ``ConfigurationLimit`` (``gain (q_min - q) <= dq <=
  gain (q_max - q)``) have no common point once a joint is past a position limit by more
  than ``v_max dt / gain``; the controller uses the project's joint box instead
  (:class:`controllers.mink.joint_box.JointBoxLimit`).
* The global ``damping`` adds ``damping * I`` to the Hessian in ``dq``: since the whole
  objective scales as ``dt^2`` it acts like the QP controller's ``mu`` on ``v``.
* A planar root joint is MuJoCo's slide x, slide y, hinge z
  (:class:`controllers.mujoco_model.PlanarBase`), which ``configuration.integrate``
  moves by ``(x, y, th) + v dt`` where Pinocchio integrates the SE(2) exponential: the
  two agree to first order in ``dt``, and mink only uses the
  velocity, never the integrated configuration.

The package: :mod:`.controller` (:class:`MinkController`, the step), :mod:`.adapters`
(constraint rows, barriers, posture and damping as mink tasks and limits), :mod:`.rows`
(the rows evaluated with Pinocchio at mink's configuration), :mod:`.joint_box` (the
project's joint box as a mink limit), :mod:`.settings` (backend settings in mink's units).
The MuJoCo model and the joint map are :mod:`controllers.mujoco_model`'s.
"""

from .controller import LimitSpec, MinkController
from .acceleration_limit import AccelerationLimit
from .joint_box import JointBoxLimit

__all__ = ["AccelerationLimit", "JointBoxLimit", "LimitSpec", "MinkController"]
