"""Each joint's reflected rotor inertia from the URDF (docs/design.md section 17.1,
"Armature").

URDF has no element for a drive's rotor; Drake's URDF extension puts one on each simple
transmission's actuator, ``<drake:rotor_inertia value="I_r"/>`` (kg m^2) and
``<drake:gear_ratio value="N"/>``, and adds ``N^2 I_r`` to the joint's diagonal of the
mass matrix, as MuJoCo's ``armature`` does. The plant reads the same two tags; a joint
without them takes the plant's ``armature`` setting. None of the built-in robots' URDFs
carries them: Yaskawa publishes no rotor inertias or gear ratios for the SDA10F, nor does
Universal Robots for the UR5.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET


def _value(element: ET.Element, where: str) -> float:
    """The element's ``value`` attribute, a finite number > 0 (``ValueError`` naming
    ``where``)."""
    text = element.get("value")
    try:
        value = float(text) if text is not None else math.nan
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        tag = element.tag.replace("drake_", "drake:")
        raise ValueError(f"{where}: {tag} value must be a finite number > 0, got {text!r}")
    return value


def urdf_armatures(urdf_text: str, where: str = "URDF") -> dict[str, float]:
    """Per joint name, ``gear_ratio^2 * rotor_inertia`` of every ``<transmission>`` whose
    ``<joint>`` names one joint and whose ``<actuator>`` carries ``rotor_inertia`` (gear
    ratio 1 when left out); ``ValueError`` naming ``where``, the transmission and the tag
    for a value that is not a finite number > 0."""
    text = urdf_text.replace("drake:", "drake_")  # read whether the prefix is declared or not
    armatures = {}
    for transmission in ET.fromstring(text).iter("transmission"):
        joints = transmission.findall("joint")
        actuator = transmission.find("actuator")
        if len(joints) != 1 or actuator is None:
            continue
        inertia, ratio = actuator.find("drake_rotor_inertia"), actuator.find("drake_gear_ratio")
        if inertia is None:
            continue
        name = f"{where}: transmission {transmission.get('name')!r}"
        gear = 1.0 if ratio is None else _value(ratio, name)
        armatures[joints[0].get("name")] = gear ** 2 * _value(inertia, name)
    return armatures
