"""The ``retraction`` experiment (docs/design.md section 21.4): through the trocar, the tool
holds a tissue flap aside at 0.5 N across the instrument while the operator moves it along
and across, under the tool-frame hybrid law on the MuJoCo plant, for any controller
(:func:`teleop.experiments.contact_run.run_contact`).

The SDA10F with the paper's hole on link 6; the flap a tissue plane 2 mm beyond the tool
tip along one axis across the instrument (the tool's x for ``retraction``, its y for
``retraction-y``), its normal against it, so the force loop along that axis closes the gap
and pushes the flap aside with 0.5 N (7.5 mm into the default tissue); the tissue has no
friction, so the tip slides on the flap. From 2.5 s for 4 s the operator's target moves in
the tool's initial frame 1 cm across the instrument along the other axis,
``1 cm sin(2 pi u)``, and 2 cm along it, ``2 cm (1 - cos(2 pi u)) / 2`` on z,
``u = (t - 2.5) / 4``, each there and back, the orientation held. A lateral force at the tip
through a port is the harder case: the tip moves across the instrument only by turning it
about the port.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .contact_run import ContactMeasures, ContactTask, run_contact

#: One line for humans (``teleop scenarios``), per force axis.
DESCRIPTION = ("through the trocar, the tool holds a tissue flap aside at 0.5 N across the "
               "instrument (the tool's x) while moving 2 cm along it and 1 cm across "
               "(hybrid force/motion; the mujoco plant)")
DESCRIPTION_Y = DESCRIPTION.replace("the tool's x", "the tool's y")
#: The force across the instrument (N), the moves along and across it (m), the phases (s).
SETPOINT, ALONG, ACROSS, SETTLE, MOVE_TIME = 0.5, 0.02, 0.01, 2.5, 4.0
#: The task's weights on the force axis, the other translations and the rotations: the
#: force axis first where the twist is not feasible.
FORCE_WEIGHT, MOTION_WEIGHT, ROTATION_WEIGHT = 100.0, 1.0, 0.01


def moves(across: int) -> Callable[[float], np.ndarray]:
    """The target's offset in the tool's initial frame at ``t`` (m), 1 cm across along the
    tool's axis ``across`` (0: x, 1: y) and 2 cm along its z."""
    def move(t: float) -> np.ndarray:
        offset = np.zeros(3)
        if SETTLE < t < SETTLE + MOVE_TIME:
            phase = 2.0 * math.pi * (t - SETTLE) / MOVE_TIME
            offset[across] = ACROSS * math.sin(phase)
            offset[2] = ALONG * 0.5 * (1.0 - math.cos(phase))
        return offset
    return move


def retraction_task(name: str, force_axis: int) -> ContactTask:
    """The experiment as a contact task: force along the tool's ``force_axis`` (0: x, 1: y),
    the moves along the other axis across the instrument and along its z."""
    weight = [MOTION_WEIGHT] * 3 + [ROTATION_WEIGHT] * 3
    weight[force_axis] = FORCE_WEIGHT
    return ContactTask(name, force_axis, SETPOINT, moves(1 - force_axis),
                       (SETTLE, SETTLE + MOVE_TIME), SETTLE + MOVE_TIME + 0.5, tuple(weight))


#: The flap across the tool's x (the moves along its y and z) and across its y (x and z).
RETRACTION = retraction_task("retraction", 0)
RETRACTION_Y = retraction_task("retraction-y", 1)


def run_retraction(spec: str, **options: Any) -> ContactMeasures:
    """:func:`~teleop.experiments.contact_run.run_contact` of :data:`RETRACTION` with
    controller ``spec`` (the options of :func:`~teleop.experiments.palpation.run_palpation`)."""
    return run_contact(RETRACTION, spec, **options)
