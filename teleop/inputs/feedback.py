"""What the operator feels: the feedback wrench (docs/design.md section 19.3).

Three terms, in the world, then turned into the device's frame and bounded:

* the **port force**: the wall's force on the instrument at each port, summed (measured
  by a physics plant; none on the ideal integrator);
* a **tracking fixture**: ``k_t (p_e - p*)`` and ``k_r log3(R_e R*^T)``, the spring from
  the target to where the tool is: what the constraints, the joint limits and the speed
  caps keep the tool from, pulling the hand back towards the tool;
* the **contact force** at the tool tip: the force/torque sensor's force from the
  environment (tool frame, turned into the world by the tool's orientation), times
  ``contact_scale``, at most ``max_contact_force`` (docs/design.md section 21.5; the
  sensor's torque is not rendered);
* an **obstacle fixture**: for each collision pair closer than the detection distance
  ``d_i``, ``k_o (d_i - d) n``, ``n`` the unit vector from the second body's witness
  point to the first's (the robot's link), pushing the hand away from the obstacle.

The force is at most ``max_force`` and the torque ``max_torque`` in norm (scaled down
whole, its direction kept): a device renders what it can, never a surprise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from constraints.collision import CollisionRows


@dataclass(frozen=True)
class FeedbackGains:
    """The fixtures' stiffnesses and the wrench's bounds."""

    tracking_stiffness: float = 100.0  # N/m
    rotation_stiffness: float = 0.5  # N m / rad
    obstacle_stiffness: float = 200.0  # N/m
    max_force: float = 5.0  # N
    max_torque: float = 0.5  # N m
    contact_scale: float = 1.0  # the hand's force per newton at the tool tip
    max_contact_force: float = 3.0  # N, the contact term alone


def bounded(vector: np.ndarray, limit: float) -> np.ndarray:
    """``vector`` scaled down to norm ``limit`` when longer (its direction kept)."""
    norm = float(np.linalg.norm(vector))
    return vector * (limit / norm) if norm > limit else vector


def feedback_wrench(ee: pin.SE3, target: pin.SE3, port_forces, rows: CollisionRows | None,
                    detection_distance: float, rotation: np.ndarray,
                    gains: FeedbackGains = FeedbackGains(),
                    tool_wrench: np.ndarray | None = None) -> np.ndarray:
    """The wrench [force; torque] to render, in the device's frame (``rotation``:
    ``R_wd``), for the tool at ``ee`` asked to ``target``; ``tool_wrench``: the sensed
    wrench from the environment at the tool (tool frame), None: no sensor."""
    force = gains.tracking_stiffness * (ee.translation - target.translation)
    if tool_wrench is not None:
        contact = gains.contact_scale * (ee.rotation @ np.asarray(tool_wrench[:3], dtype=float))
        force = force + bounded(np.nan_to_num(contact, nan=0.0, posinf=0.0, neginf=0.0),
                                gains.max_contact_force)
    torque = gains.rotation_stiffness * pin.log3(ee.rotation @ target.rotation.T)
    for port_force in port_forces:
        force = force + np.asarray(port_force, dtype=float)
    if rows is not None and rows.size:
        near = rows.distances < detection_distance
        for distance, (first, second) in zip(rows.distances[near], rows.witnesses[near]):
            away = first - second
            length = float(np.linalg.norm(away))
            if length > 1e-9:
                force = force + gains.obstacle_stiffness * (detection_distance - distance) \
                    * away / length
    force = bounded(np.nan_to_num(force, nan=0.0, posinf=0.0, neginf=0.0), gains.max_force)
    torque = bounded(np.nan_to_num(torque, nan=0.0, posinf=0.0, neginf=0.0), gains.max_torque)
    return np.concatenate([rotation.T @ force, rotation.T @ torque])
