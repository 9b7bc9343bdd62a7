"""Everything a CJM step needs, fixed until it changes (docs/design.md section 16).

:class:`StepSetup` is built by :class:`controllers.cjm.controller.CJMController` from
public data only, and built again by the controller's setters (constraints, damping
policy, posture, task weight): a step never asks whether something changed. Both
backends (:mod:`.python_step`, :mod:`.compiled`) take one. The constraints' own data
(a hole's centre and velocity, a gain) is read at every step, as data.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import pinocchio as pin

from constraints import Constraint, Parametrisation
from constraints.collision import CollisionAvoidance

from ..base import posture_difference
from ..joint_limits import BoxTest, JointBounds
from ..linalg import DampingPolicy
from .analytical import ChainSplit
from .tolerances import StepTolerances

Form = Literal["auto", "general"]


@dataclass(frozen=True)
class ConstraintPlan:
    """One constraint, the frame of its link, and its place on the chain.

    ``split``: the joints before/after its link on the path to the first EE (None when
    the EE is not downstream); ``analytical``: whether the analytical form may take it
    (one EE and its full twist, at least 6 joints before the link).
    """

    constraint: Constraint
    frame_id: int
    split: ChainSplit | None
    analytical: bool


@dataclass(frozen=True)
class StepSetup:
    """A CJM step's fixed data.

    Attributes
    ----------
    model : the robot's model.
    ee_frame_ids : the EE frames, in the order of the stacked twist.
    plans : one :class:`ConstraintPlan` per constraint, in the controller's order.
    bounds, box_test : the joint box and its fast test (docs/design.md section 8).
    policy : the DLS damping (eq 35).
    tolerances : every tolerance the step decides with.
    task_entries : the entries of the stacked twist the task keeps (weight > 0), or None
        for all of them unweighted; ``task_scale`` their ``W^1/2``.
    posture, posture_gain : the null-space posture task (gain 0: minimum norm).
    posture_free : the velocity indices the posture leaves alone (a mobile base's), or None.
    parametrisation, form : see :class:`CJMController`.
    joint_names : the joint's name per velocity index (for the messages).
    collisions : the collision pairs kept apart (docs/design.md section 18.4), or None:
        their rows ``rows qd >= lower`` are measured at every step, after the kinematics.
    """

    model: pin.Model
    ee_frame_ids: tuple[int, ...]
    plans: tuple[ConstraintPlan, ...]
    bounds: JointBounds
    box_test: BoxTest
    policy: DampingPolicy
    tolerances: StepTolerances
    task_entries: np.ndarray | None
    task_scale: np.ndarray
    posture: np.ndarray
    posture_gain: float
    posture_free: slice | None
    parametrisation: Parametrisation
    form: Form
    joint_names: tuple[str, ...]
    collisions: CollisionAvoidance | None = None

    def __post_init__(self) -> None:
        for array in (self.task_entries, self.task_scale, self.posture):
            if array is not None:
                array.flags.writeable = False

    @property
    def task_size(self) -> int:
        """Entries of the stacked twist: 6 per EE."""
        return 6 * len(self.ee_frame_ids)

    @property
    def task_rows(self) -> int:
        """Rows of the task the forms solve: 6 per EE, or those of non-zero weight."""
        return self.task_size if self.task_entries is None else self.task_entries.size

    @property
    def paper_task(self) -> bool:
        """One EE and its full, unweighted twist: the task of the analytical form."""
        return self.task_size == 6 and self.task_entries is None

    def posture_velocity(self, q: np.ndarray) -> np.ndarray:
        """``posture_gain (posture (-) q)`` (nv,), zero on ``posture_free``
        (:func:`controllers.base.posture_difference`)."""
        return self.posture_gain * posture_difference(self.model, q, self.posture,
                                                      self.posture_free)

    @property
    def constraints(self) -> tuple[Constraint, ...]:
        return tuple(plan.constraint for plan in self.plans)

    @property
    def equalities(self) -> tuple[int, ...]:
        return tuple(i for i, plan in enumerate(self.plans) if plan.constraint.is_equality)

    @property
    def barriers(self) -> tuple[int, ...]:
        return tuple(i for i, plan in enumerate(self.plans) if not plan.constraint.is_equality)
