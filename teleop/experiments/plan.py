"""What a controller run follows: the :class:`Plan` shared by scenarios and sessions."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.collision import CollisionAvoidance
from constraints.kinematics import frame_placement
from constraints.validation import as_number
from teleop.loop import Targets
from teleop.robots import Robot


@dataclass
class Plan:
    """What a controller run follows: a scenario or a recorded session.

    Attributes
    ----------
    name : scenario or session name.
    robot : the robot.
    q0 : start configuration.
    duration : seconds.
    make_constraints : returns fresh constraint objects for one run.
    target : operator target at time ``t`` (world frame): one pose per entry of
        ``robot.ee_frames`` (a single-EE plan may give the pose alone, ``teleop.loop.Targets``).
    update : called every tick with ``(t, constraints, q)``, ``q`` the robot's
        configuration at ``t``; moves geometry in place and returns a new list when the
        constraint set itself changes (else None).
    description : one line for humans.
    collisions : the collision avoidance the plan declares (``CollisionAvoidance.to_dict()``:
        the damper's settings and the obstacles), None: none (docs/design.md 18.6);
        :meth:`make_collisions` builds a fresh one per controller and per measure.
    constraint_gain : the drift-feedback gain (1/s) every constraint is given
        (:meth:`with_constraint_gain`), None: each keeps its own.
    task_modes : what the operator commands of each EE at time ``t`` (docs/design.md
        section 20: one mode per EE), None: as before (the full pose at the start).
    """

    name: str
    robot: Robot
    q0: np.ndarray
    duration: float
    make_constraints: Callable[[], list[Constraint]]
    target: Callable[[float], Targets]
    update: Callable[[float, list[Constraint], np.ndarray], list[Constraint] | None] = field(
        default=lambda t, constraints, q: None)
    description: str = ""
    collisions: dict | None = None
    constraint_gain: float | None = None
    task_modes: Callable[[float], tuple[str, ...] | None] = field(default=lambda t: None)

    def make_collisions(self) -> CollisionAvoidance | None:
        """A fresh collision avoidance on the plan's robot with its own obstacles, or None."""
        if self.collisions is None:
            return None
        return CollisionAvoidance.from_dict(self.robot, self.collisions)

    def with_constraint_gain(self, gain: float) -> "Plan":
        """A new plan whose constraints all have the drift-feedback gain ``K = gain`` (1/s,
        finite, >= 0; ``ValueError`` naming ``constraint_gain``), those of
        ``make_constraints`` and those ``update`` adds alike (docs/design.md 15.1.1).
        Whether ``K dt < 2`` (1 for a barrier) holds depends on the control period: the
        run checks it (:func:`teleop.experiments.compare.check_constraint_gain`)."""
        gain = as_number(gain, "constraint_gain", 0.0)
        make, update = self.make_constraints, self.update

        def with_gain(constraints: list[Constraint]) -> list[Constraint]:
            for constraint in constraints:
                constraint.gain = gain
            return constraints

        def make_constraints() -> list[Constraint]:
            return with_gain(make())

        def update_with_gain(t: float, constraints: list[Constraint],
                             q: np.ndarray) -> list[Constraint] | None:
            changed = update(t, constraints, q)
            return None if changed is None else with_gain(changed)

        return replace(self, make_constraints=make_constraints, update=update_with_gain,
                       constraint_gain=gain)

    def with_response_time(self, response_time: float) -> "Plan":
        """The plan whose collision damper counts on a robot ``response_time`` (s) late
        (``CollisionAvoidance``'s ``response_time``: the damper's rate ``1 / K = (d_i -
        d_s) / xi + tau``, docs/design.md 18.3); the plan itself without collision
        avoidance or with a response time of 0 (a robot moving as commanded)."""
        if self.collisions is None or not response_time:
            return self
        return replace(self, collisions={**self.collisions, "response_time": response_time})


def smoothstep(x: float) -> float:
    """0 -> 1 with zero slope and curvature at both ends (quintic)."""
    x = min(max(x, 0.0), 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0)


def home_pose(robot: Robot, q: np.ndarray) -> pin.SE3:
    """World placement of the (first) EE at ``q``."""
    return frame_placement(robot.model, q, robot.ee_frame)


def home_poses(robot: Robot, q: np.ndarray) -> list[pin.SE3]:
    """World placement of every EE at ``q``, in ``robot.ee_frames`` order."""
    return [frame_placement(robot.model, q, frame) for frame in robot.ee_frames]


def link_placement(robot: Robot, q: np.ndarray, link: str) -> pin.SE3:
    """World placement of ``link`` at ``q``."""
    return frame_placement(robot.model, q, link)


