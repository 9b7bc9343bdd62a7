"""Frames and forward kinematics at a configuration: the one helper every layer uses."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .validation import as_vector


def resolve_frame(model: pin.Model, frame: str) -> int:
    """Frame id of ``frame`` in ``model``; unknown names raise ``ValueError`` naming it."""
    if not isinstance(frame, str) or not model.existFrame(frame):
        bodies = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
        raise ValueError(f"unknown link {frame!r}; the model's links are {bodies}")
    return model.getFrameId(frame)


def frame_placement(model: pin.Model, q: np.ndarray, frame: str | int,
                    data: pin.Data | None = None) -> pin.SE3:
    """World placement of ``frame`` (a name or a frame id) at configuration ``q``.

    ``q`` is validated; pass ``data`` to reuse a ``pin.Data`` (it is overwritten).
    """
    q = as_vector(q, model.nq, "q")
    frame_id = frame if isinstance(frame, int) else resolve_frame(model, frame)
    data = model.createData() if data is None else data
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[frame_id].copy()
