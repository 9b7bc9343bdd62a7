"""The true minimum distance of the robot's collision pairs, measured by the closed loop
(docs/design.md section 18.6).

At the end of every period the loop measures, at the robot's true configuration, the
smallest distance over the pairs a :class:`~constraints.collision.CollisionAvoidance`
keeps apart, with that avoidance's bounding-sphere broadphase (its ``rows``). The
broadphase keeps every pair whose bounding spheres come within the detection distance
``d_i``, so every pair closer than ``d_i`` is measured: the minimum is exact whenever it
is below ``d_i``, which is where penetrations (``d < 0``) and safety violations
(``d < d_s -`` :data:`SAFETY_TOLERANCE`) live. Above ``d_i`` it is the nearest pair the
broadphase measured (an upper bound on the true minimum), or ``inf`` when it measured
none. Checking every pair (``CollisionAvoidance.minimum_distance``) would cost more at
every period (docs/design.md 18.6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.collision import CollisionAvoidance

#: How far below the safety distance ``d_s`` a pair may come before the step counts as a
#: safety violation (m): issue 21's bound, ``d >= d_s - 0.5 mm``.
SAFETY_TOLERANCE = 0.5e-3


@dataclass(frozen=True)
class DistanceMeasure:
    """One period's measure: the smallest distance (m; ``inf``: no pair measured) and its
    pair (``"first | second"``, "" when none)."""

    minimum_distance: float
    closest_pair: str


class DistanceMeter:
    """Measures the minimum distance of ``collisions``' pairs at the true configuration and
    counts the periods with a penetration or a safety violation.

    ``collisions`` must be the meter's own (not a controller's: its rows and placements are
    overwritten by each measure); its ports follow the loop's constraints
    (:meth:`set_constraints`), so the instrument inside a port is not measured against
    the body it goes through.
    """

    def __init__(self, collisions: CollisionAvoidance) -> None:
        if not isinstance(collisions, CollisionAvoidance):
            raise ValueError(f"collisions must be a CollisionAvoidance, got "
                             f"{type(collisions).__name__}")
        self.collisions = collisions
        self.penetrations = 0
        self.safety_violations = 0

    @property
    def violation_distance(self) -> float:
        """Below this distance (m) a period counts as a safety violation."""
        return self.collisions.safety_distance - SAFETY_TOLERANCE

    def set_constraints(self, constraints: list[Constraint]) -> None:
        """The loop's constraints changed: the ports exempt from obstacles follow them."""
        self.collisions.set_ports(constraints)

    def reset(self) -> None:
        """Forget the counts."""
        self.penetrations = self.safety_violations = 0

    def measure(self, model: pin.Model, data: pin.Data, q: np.ndarray) -> DistanceMeasure:
        """The minimum distance at ``q`` (``data`` is overwritten), counted."""
        pin.computeJointJacobians(model, data, q)
        rows = self.collisions.rows(model, data)
        distance = float(rows.minimum_distance)
        self.penetrations += distance < 0.0
        self.safety_violations += distance < self.violation_distance
        return DistanceMeasure(distance, rows.closest_pair)
