"""Moving a constraint's geometry while the robot holds it: speed-capped, fed forward.

A hole dragged 5 cm in the browser, or a session event that jumps a plane, must not reach
the controllers as a step. The geometry moves like a first-order integrator of its
velocity: at each tick :func:`steer` picks the velocity for the coming period (towards
where it was put, at most :data:`MAX_GEOMETRY_SPEED`), the controllers feed that
velocity forward (docs/design.md section 3.4), and :func:`advance` moves the geometry by
it once the period has passed, before the tick's measures are taken.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

#: Fastest a hole, plane or lock target moves (m/s). A hole moving across the shaft at
#: this speed swings the sda10f's link 6 at about 0.4 rad/s per 5 cm of lever: inside the
#: joint-velocity limits of both built-in robots, with room for the operator's own motion.
MAX_GEOMETRY_SPEED = 0.02


class MovingGeometry(Protocol):
    """What moves here: a world reference point (m) and its velocity (m/s), both set by
    :meth:`move_to` (a constraint's geometry, an obstacle)."""

    velocity: np.ndarray

    @property
    def position(self) -> np.ndarray: ...

    def move_to(self, position: np.ndarray, velocity: ArrayLike) -> None: ...


def advance(constraint: MovingGeometry, elapsed: float) -> None:
    """The geometry after ``elapsed`` s at its current velocity (velocity kept)."""
    if elapsed > 0.0 and np.any(constraint.velocity):
        constraint.move_to(constraint.position + constraint.velocity * elapsed, constraint.velocity)


def steer(constraint: MovingGeometry, goal: np.ndarray, dt: float, smoothing: float = 1.0,
          max_speed: float = MAX_GEOMETRY_SPEED) -> None:
    """Set the velocity that moves the geometry towards ``goal`` (world, m) over ``dt``.

    The step is ``smoothing`` (in (0, 1]: a first-order filter's ``1 - exp(-dt / tau)``)
    times the remaining distance, capped at ``max_speed dt``; the position is unchanged.
    """
    step = smoothing * (np.asarray(goal, dtype=float) - constraint.position)
    distance = float(np.linalg.norm(step))
    if distance > max_speed * dt:
        step *= max_speed * dt / distance
    velocity = step / dt
    if not np.array_equal(velocity, constraint.velocity):
        constraint.move_to(constraint.position, velocity)
