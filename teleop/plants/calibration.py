"""Calibration error: the real robot's kinematics differ from the controllers' model
(docs/design.md section 15.1, "Calibration error").

Every joint placement ``M_j`` (``model.jointPlacements[j]``, the joint's frame in its
parent's, ``j >= 1``) of the true robot is the model's times a small rigid error in the
coordinates of ``M_j``::

    M_j,true = M_j E_j,   E_j = (exp3(r_j), t_j),   t_j ~ N(0, s_m^2 I_3),   r_j ~ N(0, s_rad^2 I_3)

drawn once per run from a stream of its own (:data:`CALIBRATION_STREAM`): the encoder
noise of the same seed draws the same sequence with or without it.
"""

from __future__ import annotations

import pinocchio as pin

from teleop.seeds import stream

#: The calibration draw's stream of the seed (:func:`teleop.seeds.stream`): apart from the
#: encoder noise's ``default_rng(seed)`` and from every other seed's streams.
CALIBRATION_STREAM = 0xCA1

#: Per joint, the draw's columns: the translation's three, then the rotation vector's three.
DRAWS_PER_JOINT = 6


def joint_placement_errors(joints: int, position_std: float, rotation_std: float,
                           seed: int) -> list[pin.SE3]:
    """The rigid errors ``E_1 .. E_joints`` of the module's formula, in joint order.

    One ``(joints, 6)`` block of standard normals ``z`` is drawn from
    ``stream(seed, CALIBRATION_STREAM)``; ``t_j = s_m z_j[:3]`` and
    ``r_j = s_rad z_j[3:]``. The same seed gives the same ``z`` whatever the stds, so
    a zero std leaves the other part of the draw as it was.
    """
    normals = stream(seed, CALIBRATION_STREAM).standard_normal((joints, DRAWS_PER_JOINT))
    return [pin.SE3(pin.exp3(rotation_std * row[3:]), position_std * row[:3])
            for row in normals]


def miscalibrated_model(model: pin.Model, position_std: float, rotation_std: float,
                        seed: int) -> pin.Model:
    """A copy of ``model`` whose joint placements carry the calibration error:
    ``M_j,true = M_j E_j`` for every joint ``j >= 1`` (:func:`joint_placement_errors`,
    ``position_std`` in m, ``rotation_std`` in rad); frames, inertias and limits as the
    model's. ``model`` itself is not changed."""
    true_model = pin.Model(model)
    errors = joint_placement_errors(model.njoints - 1, position_std, rotation_std, seed)
    for joint, error in enumerate(errors, start=1):
        true_model.jointPlacements[joint] = model.jointPlacements[joint] * error
    return true_model
