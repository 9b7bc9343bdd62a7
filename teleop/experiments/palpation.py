"""The ``palpation`` experiment (docs/design.md section 21.4): through the trocar, the tool
tip presses a tissue surface at 1 N along the tool's axis and slides 2 cm across it and
back, under the tool-frame hybrid law (:class:`teleop.loop.HybridForceMotion`) on the
MuJoCo plant, for any controller (:func:`teleop.experiments.contact_run.run_contact`).

The SDA10F with the paper's hole on link 6; the tissue plane 2 mm beyond the tool tip at
the start, its normal against the tool's z axis (the instrument's), so the force loop
along the tool's z first closes the gap and presses (at most 1 cm/s), then holds 1 N (a
15 mm penetration of the default tissue). After 2.5 s the operator's target
slides along the tool's x at the start, ``s(t) = 2 cm (1 - cos(2 pi (t - 2.5) / 4)) / 2`` for
4 s (out and back), the orientation held; the loop's pose feedback
``K_p log6(T^-1 T*)`` (body twist) gives the twist on the free axes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .contact_run import ContactMeasures, ContactTask, run_contact

#: One line for humans (``teleop scenarios``).
DESCRIPTION = ("through the trocar, the tip presses tissue at 1 N along the tool and slides 2 cm "
               "across it and back (hybrid force/motion; the mujoco plant)")
#: The force the tool exerts along its z (N), the slide (m), the phases (s).
SETPOINT, SLIDE, SETTLE, SLIDE_TIME = 1.0, 0.02, 2.5, 4.0
#: The task's weight: the force axis (tool z) first where the twist is not feasible.
TWIST_WEIGHT = (1.0, 1.0, 100.0, 0.01, 0.01, 0.01)


def slide(t: float) -> float:
    """The target's offset along the tool's initial x at ``t`` (m)."""
    if t <= SETTLE or t >= SETTLE + SLIDE_TIME:
        return 0.0
    return SLIDE * 0.5 * (1.0 - math.cos(2.0 * math.pi * (t - SETTLE) / SLIDE_TIME))


#: The experiment as a contact task: force along the tool's z, the slide along its x.
PALPATION = ContactTask("palpation", 2, SETPOINT, lambda t: np.array([slide(t), 0.0, 0.0]),
                        (SETTLE, SETTLE + SLIDE_TIME), SETTLE + SLIDE_TIME + 0.5, TWIST_WEIGHT)


def run_palpation(spec: str, **options: Any) -> ContactMeasures:
    """:func:`~teleop.experiments.contact_run.run_contact` of :data:`PALPATION` with
    controller ``spec`` (its options: ``dt``, ``duration``, ``sensor_noise``,
    ``sensor_bias``, ``seed``, ``tare_samples``, ``plant``, ``acceleration_limits``,
    ``jerk_limit``, ``force_filter``)."""
    return run_contact(PALPATION, spec, **options)
