"""The real robot's kinematics where they differ from the controllers' model (a calibration
error, docs/design.md section 15.1, "Calibration error").

The controller computes with the model; the loop's measures at the true configuration take
the true model. A constraint's geometry is where the real instrument met it: when the loop
first meets a constraint on link ``a`` at the true configuration ``q``, it registers

    G = T_true,a(q) T_model,a(q)^-1

and from then on measures the constraint with its current world geometry moved by ``G``
(:meth:`constraints.Constraint.moved`). The error is then the model's at registration
(zero for a hole placed where the link is) and grows as the robot moves under the wrong
model; geometry that moves (a breathing trocar) keeps its ``G``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint


class TrueKinematics:
    """The true model, its data and the registered offset ``G`` of every constraint met.

    Parameters
    ----------
    model : the controllers' model.
    true_model : the real robot's: the same joints and frames, other placements
        (``ValueError`` otherwise).
    """

    def __init__(self, model: pin.Model, true_model: pin.Model) -> None:
        if not isinstance(true_model, pin.Model):
            raise ValueError(f"true_model must be a pin.Model, got {type(true_model).__name__}")
        for size in ("nq", "nv", "njoints", "nframes"):
            if getattr(true_model, size) != getattr(model, size):
                raise ValueError(f"true_model must have the model's joints and frames: its "
                                 f"{size} is {getattr(true_model, size)}, the model's "
                                 f"{getattr(model, size)}")
        self.model = true_model
        self.data = true_model.createData()
        self._nominal = model
        self._nominal_data = model.createData()
        self._registration_data = true_model.createData()
        #: per constraint (by id, the object kept so the id stays its own): the constraint
        #: and its offset G
        self._offsets: dict[int, tuple[Constraint, pin.SE3]] = {}

    def offset(self, constraint: Constraint, frame: int, q: np.ndarray) -> pin.SE3:
        """``G = T_true(frame, q) T_model(frame, q)^-1``, computed at ``q`` the first time
        ``constraint`` is met and kept."""
        entry = self._offsets.get(id(constraint))
        if entry is None or entry[0] is not constraint:
            pin.framesForwardKinematics(self._nominal, self._nominal_data, q)
            pin.framesForwardKinematics(self.model, self._registration_data, q)
            motion = (self._registration_data.oMf[frame]
                      * self._nominal_data.oMf[frame].inverse())
            entry = (constraint, motion)
            self._offsets[id(constraint)] = entry
        return entry[1]

    def constraints(self, constraints: Sequence[Constraint], frames: Sequence[int],
                    q: np.ndarray) -> list[Constraint]:
        """Each constraint as the real robot meets it: a copy of its current geometry moved
        by its offset (registered at the true configuration ``q`` when first met)."""
        return [constraint.moved(self.offset(constraint, frame, q))
                for constraint, frame in zip(constraints, frames)]
