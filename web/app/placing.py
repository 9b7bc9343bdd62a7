"""Placing a constraint from its type's registered placement: the operator's values,
checked by field type (:mod:`web.placement_fields`), become the keywords of the placement's
``place`` (:mod:`web.constraint_placement`, docs/design.md section 5.5). Nothing here
knows a constraint kind."""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.validation import as_number, as_vector
from teleop.robots import Robot

from ..constraint_placement import placement_of
from ..placement_fields import PlacementField
from .limits import MAX_LINK_POINT

#: the field types that say where on the link the constrained point is
POINT_FIELDS = ("distance", "link_point")


def moving_links(robot: Robot) -> tuple[str, ...]:
    """The links a ``"moving"`` link field offers: the constrained links (one per arm)
    first, then every other link that moves (a mobile base's ``mobile_base``...)."""
    model = robot.model
    moving = [frame.name for frame in model.frames
              if frame.type == pin.FrameType.BODY and frame.parentJoint != 0]
    return tuple(dict.fromkeys((*robot.constrained_links, *moving)))


def link_choices(robot: Robot, field: PlacementField) -> tuple[str, ...]:
    """The links a link ``field`` offers on ``robot``."""
    return tuple(robot.constrained_links) if field.links == "constrained" else moving_links(robot)


def arm_ee(robot: Robot, link: str) -> str:
    """The EE frame on ``link``'s arm: the first whose chain carries the link (a link
    before every arm, such as the torso or a mobile base, gives the first EE)."""
    model = robot.model
    joint = model.frames[model.getFrameId(link)].parentJoint
    return next((frame for frame in robot.ee_frames
                 if joint in model.supports[model.frames[model.getFrameId(frame)].parentJoint]),
                robot.ee_frame)


def field_applies(field: PlacementField, robot: Robot, link: str | None) -> bool:
    """Whether ``field`` takes a value on ``link``: a distance on a link with an
    instrument axis, a link point on one without; every other field always."""
    if field.type == "distance":
        return link in robot.link_axes
    if field.type == "link_point":
        return link not in robot.link_axes
    return True


class Placement:
    """The checks of one placement: ``constraint_type``'s fields on ``robot``, with
    ``placement_of(link)`` the world placement of a link of the main robot now."""

    def __init__(self, constraint_type: type[Constraint], robot: Robot,
                 placement_of: Callable[[str], pin.SE3]) -> None:
        self.type = constraint_type
        self.label = constraint_type.label
        self.robot = robot
        self.placement_of = placement_of

    def values(self, given: Mapping) -> dict:
        """The keywords of ``place`` from the operator's ``given`` values: a field not
        given takes its declared default; a bad value raises ``ValueError`` naming it."""
        placement = placement_of(self.type)
        if placement is None:
            raise ValueError(f"a {self.label} is not placed from the UI: its type registers "
                             "no placement")
        declared = {field.name: field for field in placement.fields}
        for name in given:
            if name not in declared:
                raise ValueError(f"unknown field {name!r} for a {self.label} (its fields: "
                                 f"{', '.join(declared)})")
        links = [field for field in declared.values() if field.type == "link"]
        link = self._link(links[0], given.get(links[0].name)) if links else None
        values = {} if link is None else {links[0].name: link}
        for field in declared.values():
            if field.type == "link":
                continue
            if not field_applies(field, self.robot, link):
                if field.name in given:
                    raise ValueError(self._not_applicable(field, link))
                continue
            values[field.name] = self._value(field, given.get(field.name, field.default), link)
        points = [field for field in declared.values() if field.type in POINT_FIELDS]
        if points and not any(field.name in values for field in points):
            raise ValueError(f"{link} has no instrument axis: a {self.label} needs a "
                             "distance along one")
        return values

    def _link(self, field: PlacementField, link) -> str:
        choices = link_choices(self.robot, field)
        constrained = self.robot.constrained_links
        if not constrained and (link is None or field.links == "constrained"):
            raise ValueError(
                "this robot has no constrained link: start `teleop web` with "
                f"--constrained-link LINK (and --link-axis X Y Z) to place a {self.label}")
        if link is None:
            return constrained[0]
        if link not in choices:
            if field.links == "constrained":
                raise ValueError(f"a {self.label} goes on a constrained link: one of "
                                 f"{list(choices)}, got {link!r}")
            raise ValueError(f"no link {link!r} to put a {self.label} on: one of {list(choices)}")
        return link

    def _not_applicable(self, field: PlacementField, link: str) -> str:
        if field.type == "distance":
            return (f"{link} has no instrument axis: give the {self.label}'s point on it in "
                    "link coordinates (m)")
        return (f"a {self.label} on {link} goes through a point on its axis: give its "
                "distance, not a link point")

    def _value(self, field: PlacementField, value, link: str | None):
        name = f"{self.label} {field.name.replace('_', ' ')}"
        if field.type == "distance":
            return self._distance(as_number(value, name), name, link)
        if field.type == "link_point":
            point = as_vector(value, 3, name)
            if np.linalg.norm(point) > MAX_LINK_POINT:
                raise ValueError(f"the {self.label}'s link point must be within "
                                 f"{MAX_LINK_POINT:g} m of {link}'s origin")
            return point
        if field.type == "direction":
            direction = as_vector(value, 3, name)
            norm = float(np.linalg.norm(direction))
            if norm < 1e-9:
                raise ValueError(f"the {name} must be a non-zero 3-vector")
            return direction / norm
        return as_number(value, name, field.minimum, maximum=field.maximum)

    def _distance(self, distance: float, name: str, link: str) -> float:
        """``distance`` (m along ``link``'s axis) if it lies on the arm: between the link's
        joint (0) and the distance of that arm's EE from it; else ``ValueError``."""
        placement = self.placement_of(link)
        reach = float(np.linalg.norm(placement.actInv(
            self.placement_of(arm_ee(self.robot, link)).translation)))
        if not 0.0 <= distance <= reach:
            raise ValueError(f"{name} must be between 0 and {reach:.3f} m (from the joint of "
                             f"{link} to the tool tip), got {distance:g} m")
        return distance
