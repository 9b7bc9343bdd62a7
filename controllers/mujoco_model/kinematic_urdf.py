"""The URDF MuJoCo compiles: kinematics only, locked joints made fixed."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence

import numpy as np
import pinocchio as pin


def kinematic_urdf(urdf_text: str, locked_joints: Mapping[str, Sequence[float]]) -> str:
    """The URDF with its ``<visual>``/``<collision>`` elements removed and the locked joints
    made fixed.

    MuJoCo would otherwise try to load every mesh (``package://`` URIs it cannot
    resolve); only the kinematics matter to mink. Inertials are kept. A joint the robot
    was loaded with locked (``teleop.load_robot(..., locked_joints=...)``, Pinocchio's
    ``buildReducedModel``) becomes a fixed joint whose origin carries its motion at the
    locked position, so both models have the same joints and the same frames.
    """
    root = ET.fromstring(urdf_text)
    if root.tag != "robot":
        raise ValueError(f"not a URDF: root element is <{root.tag}>, expected <robot>")
    for link in root.iter("link"):
        for child in [c for c in link if c.tag in ("visual", "collision")]:
            link.remove(child)
    joints = {joint.get("name"): joint for joint in root.iter("joint")}
    for name, position in locked_joints.items():
        if name not in joints:
            raise ValueError(f"locked joint {name!r} is not in the URDF")
        fix_joint(joints[name], position)
    for extension in [c for c in root if c.tag == "mujoco"]:
        root.remove(extension)
    compiler = ET.SubElement(ET.SubElement(root, "mujoco"), "compiler")
    compiler.set("discardvisual", "true")
    compiler.set("fusestatic", "true")
    return ET.tostring(root, encoding="unicode")


def fix_joint(joint: ET.Element, position: Sequence[float]) -> None:
    """Turn a URDF ``<joint>`` into a fixed one at ``position`` (its Pinocchio coordinates:
    an angle, a displacement, or ``(cos, sin)`` for a continuous joint).

    The new origin is ``T_origin * T_motion(position)``: a rotation about the joint axis
    (revolute, continuous) or a translation along it (prismatic), in URDF conventions
    (``rpy`` is ``Rz(y) Ry(p) Rx(r)``, Pinocchio's ``rpyToMatrix``).
    """
    kind = joint.get("type")
    axis_element = joint.find("axis")
    axis = np.array([float(x) for x in (axis_element.get("xyz", "1 0 0") if axis_element is not None
                                        else "1 0 0").split()])
    axis /= np.linalg.norm(axis)
    values = [float(x) for x in position]
    if kind in ("revolute", "continuous"):
        angle = math.atan2(values[1], values[0]) if len(values) == 2 else values[0]
        motion = pin.SE3(pin.exp3(angle * axis), np.zeros(3))
    elif kind == "prismatic":
        motion = pin.SE3(np.eye(3), values[0] * axis)
    else:
        raise ValueError(f"joint {joint.get('name')!r}: locking a {kind!r} joint is not supported "
                         "(revolute, continuous and prismatic only)")
    origin_element = joint.find("origin")
    if origin_element is None:
        origin_element = ET.SubElement(joint, "origin")
    xyz = [float(x) for x in origin_element.get("xyz", "0 0 0").split()]
    rpy = [float(x) for x in origin_element.get("rpy", "0 0 0").split()]
    fixed = pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(xyz)) * motion
    origin_element.set("xyz", " ".join(repr(float(x)) for x in fixed.translation))
    origin_element.set("rpy", " ".join(repr(float(x)) for x in pin.rpy.matrixToRpy(fixed.rotation)))
    joint.set("type", "fixed")
    for child in [c for c in joint if c.tag in ("axis", "limit", "mimic", "dynamics",
                                                 "safety_controller", "calibration")]:
        joint.remove(child)
