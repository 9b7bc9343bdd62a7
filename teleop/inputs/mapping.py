"""From a device's motion to its end effector's target: the view's frame, the clutch,
the motion scale (docs/design.md section 19.1, the dVRK's convention).

The device's frame is the operator's view: x to the right of the screen, y up, z
towards the operator. Its orientation in the world, ``R_wd``, follows the browser's
camera (viser's camera is OpenCV's: x right, y down, z forward, so ``R_wd = R_wc
diag(1, -1, -1)``). Each sample moves the target by the device's motion since the
previous sample, mapped with the view of that instant; so the view, the motion scale
``s`` and the clutch can all change while the operator holds the device, and the target
never jumps:

    p*  <-  p* + s R_wd (p_k - p_k-1)
    R*  <-  R_wd (R_k R_k-1^T) R_wd^T R*           orientation relative (default)
    R*  <-  R_wd R_k                               orientation absolute to the view

and a rate command (a twist ``v, w`` in the device's frame) over a period ``dt``:

    p*  <-  p* + s R_wd v dt,     R*  <-  exp3(R_wd w dt) R*
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

#: the device's axes in viser's (OpenCV) camera frame: x right, y up, z back
DEVICE_IN_CAMERA = np.diag([1.0, -1.0, -1.0])
#: ``R_wd`` before any browser has said where it looks: an operator facing the world's +x
#: axis, z up (right = -y, up = +z, towards the operator = -x)
DEFAULT_VIEW = np.array([[0.0, 0.0, -1.0],
                         [-1.0, 0.0, 0.0],
                         [0.0, 1.0, 0.0]])


def view_rotation(camera_wxyz) -> np.ndarray:
    """``R_wd``: the device's frame in the world for a camera oriented ``camera_wxyz``
    (viser's ``client.camera.wxyz``, OpenCV convention)."""
    w, x, y, z = (float(v) for v in camera_wxyz)
    camera = pin.Quaternion(w, x, y, z).normalized().matrix()
    return camera @ DEVICE_IN_CAMERA


def device_pose(values) -> pin.SE3:
    """A pose sample's values (x y z, quaternion w x y z) as a pose."""
    x, y, z, qw, qx, qy, qz = values
    return pin.SE3(pin.Quaternion(qw, qx, qy, qz).normalized().matrix(), np.array([x, y, z]))


def followed_pose(target: pin.SE3, previous: pin.SE3, current: pin.SE3, rotation: np.ndarray,
                  scale: float, absolute_orientation: bool = False) -> pin.SE3:
    """The target moved by the device's motion from ``previous`` to ``current`` (device
    frame), mapped by ``rotation`` (``R_wd``) and scaled by ``scale``."""
    position = target.translation + scale * rotation @ (current.translation
                                                         - previous.translation)
    if absolute_orientation:
        orientation = rotation @ current.rotation
    else:
        turn = current.rotation @ previous.rotation.T
        orientation = rotation @ turn @ rotation.T @ target.rotation
    return pin.SE3(orientation, position)


def integrated_twist(target: pin.SE3, twist, rotation: np.ndarray, scale: float,
                     dt: float) -> pin.SE3:
    """The target moved for ``dt`` by the rate command ``twist`` (v, w in the device's
    frame), mapped by ``rotation`` (``R_wd``), the linear part scaled by ``scale``."""
    twist = np.asarray(twist, dtype=float)
    position = target.translation + scale * dt * (rotation @ twist[:3])
    orientation = pin.exp3(dt * (rotation @ twist[3:6])) @ target.rotation
    return pin.SE3(orientation, position)
