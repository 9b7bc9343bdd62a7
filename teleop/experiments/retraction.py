"""The ``retraction`` experiment (docs/design.md section 21.4): through the trocar, the tool
holds a tissue flap aside at 0.5 N across the instrument while the operator moves it along
and across, under the tool-frame hybrid law on the MuJoCo plant, for any controller
(:func:`teleop.experiments.contact_run.run_contact`).

The SDA10F with the paper's hole on link 6; the flap a tissue plane 2 mm beyond the tool
tip along the tool's x (across the instrument), its normal against it, so the force loop
along the tool's x closes the gap and pushes the flap aside with 0.5 N (7.5 mm into the
default tissue); the tissue has no friction, so the tip slides on the flap. From 2.5 s
for 4 s the operator's target moves in the tool's initial frame by
``(0, 1 cm sin(2 pi u), 2 cm (1 - cos(2 pi u)) / 2)``, ``u = (t - 2.5) / 4``: 2 cm along
the instrument (out of the body and back) and 1 cm across it, each there and back, the
orientation held. A lateral force at the tip through a port is the harder case: the tip
moves across the instrument only by turning it about the port.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .contact_run import ContactMeasures, ContactTask, run_contact

#: One line for humans (``teleop scenarios``).
DESCRIPTION = ("through the trocar, the tool holds a tissue flap aside at 0.5 N across the "
               "instrument while moving 2 cm along it and 1 cm across (hybrid force/motion; "
               "the mujoco plant)")
#: The force across the instrument (N), the moves along and across it (m), the phases (s).
SETPOINT, ALONG, ACROSS, SETTLE, MOVE_TIME = 0.5, 0.02, 0.01, 2.5, 4.0
#: The task's weight: the force axis (tool x) first where the twist is not feasible.
TWIST_WEIGHT = (100.0, 1.0, 1.0, 0.01, 0.01, 0.01)


def move(t: float) -> np.ndarray:
    """The target's offset in the tool's initial frame at ``t`` (m)."""
    if t <= SETTLE or t >= SETTLE + MOVE_TIME:
        return np.zeros(3)
    phase = 2.0 * math.pi * (t - SETTLE) / MOVE_TIME
    return np.array([0.0, ACROSS * math.sin(phase), ALONG * 0.5 * (1.0 - math.cos(phase))])


#: The experiment as a contact task: force along the tool's x, the moves along its y, z.
RETRACTION = ContactTask("retraction", 0, SETPOINT, move, (SETTLE, SETTLE + MOVE_TIME),
                         SETTLE + MOVE_TIME + 0.5, TWIST_WEIGHT)


def run_retraction(spec: str, **options: Any) -> ContactMeasures:
    """:func:`~teleop.experiments.contact_run.run_contact` of :data:`RETRACTION` with
    controller ``spec`` (the options of :func:`~teleop.experiments.palpation.run_palpation`)."""
    return run_contact(RETRACTION, spec, **options)
