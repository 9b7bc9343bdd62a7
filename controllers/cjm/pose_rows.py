"""A pose as a row of 12 floats, as the compiled step and tick hold them (docs/design.md
16): the rotation row-major, then the translation; and the compiled tick's period, one row
per EE (the filtered target, the previous target, the EE placement, each a pose row, then
the commanded twist, 6). The one description of both layouts on the Python side; the
C++ side's is ``_step/pose_row.hpp`` (controllers/cjm/compiled_tick.py checks they agree).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import pinocchio as pin

#: floats in a pose row, and where its translation starts (after the rotation's 9)
POSE_ROW = 12
POSE_TRANSLATION = 9
#: the compiled tick's period row: where each part of an EE's entry is
PERIOD_TARGET = slice(0, POSE_ROW)
PERIOD_PREVIOUS = slice(POSE_ROW, 2 * POSE_ROW)
PERIOD_PLACEMENT = slice(2 * POSE_ROW, 3 * POSE_ROW)
PERIOD_TWIST = slice(3 * POSE_ROW, 3 * POSE_ROW + 6)


def pose_rows(poses: Sequence[pin.SE3] | None, count: int) -> np.ndarray:
    """``poses`` as ``count`` pose rows; zeros for None (or past the poses given)."""
    rows = np.zeros((count, POSE_ROW))
    for row, pose in zip(rows, poses or ()):
        row[:POSE_TRANSLATION], row[POSE_TRANSLATION:] = pose.rotation.ravel(), pose.translation
    return rows


def row_pose(row: np.ndarray) -> pin.SE3:
    """The pose in a pose row."""
    return pin.SE3(*row_views(row))


def row_views(row: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Views of a pose row's rotation (3 x 3) and translation (3,), which follow the row."""
    return row[:POSE_TRANSLATION].reshape(3, 3), row[POSE_TRANSLATION:POSE_ROW]
