"""Each constraint drawn from its geometry (:func:`web.constraint_drawing.constraint_geometry`):
its shape (a ring around its link, a translucent square, a sphere), the constrained point
as a collar around its link, the error as a short vector (drawn x100) when it is not zero,
an arrow to a one-sided constraint's allowed side and, on the main robot, a label naming
it and the link it is on ("<id> on <link>"). A constraint is a placed item: its gizmo, its
redrawing and its removal are :class:`web.ui.placed_markers.PlacedMarkers`'."""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin
import viser

from teleop.robots import Robot

from ..constraint_drawing import ConstraintGeometry
from .shapes import (
    MIN_RING_RADIUS,
    SQUARE_SIZE,
    LinkProfile,
    arrow_segments,
    ring_around,
    ring_segments,
    wxyz_from_z,
)

ERROR_VECTOR_SCALE = 100.0
ALLOWED_SIDE_ARROW = 0.08  # m
POINT_COLOR = (20, 20, 20)
ERROR_COLOR = (255, 0, 255)
#: a constraint's label is this far above its anchor (m), clear of its ring and gizmo
LABEL_HEIGHT = 0.06


class ConstraintDrawer:
    """The scene nodes of a constraint (an :class:`web.ui.placed_markers.ItemDrawer`) from
    its drawing (a snapshot's constraint: its geometry, link, link placement and axis):
    ``"shape"``, ``"point"``, ``"error"``, and ``"arrow"`` where it applies, ``"label"``
    when ``labelled`` (the main robot's). Rings and collars go outside the link's geometry
    (``profiles``, :class:`web.ui.shapes.LinkProfile`), squares as wide as the link
    (``square_sizes``, m)."""

    def __init__(self, server: viser.ViserServer, robot: Robot,
                 profiles: dict[str, LinkProfile], square_sizes: dict[str, float],
                 labelled: bool) -> None:
        self.server = server
        self.robot = robot
        self.profiles = profiles
        self.square_sizes = square_sizes
        self.labelled = labelled

    def create(self, name: str, entry_id: str, drawing: dict) -> dict[str, Any]:
        """The constraint's nodes under ``name``."""
        scene = self.server.scene
        geometry: ConstraintGeometry = drawing["geometry"]
        markers: dict[str, Any] = {"shape": self._add_shape(name, drawing)}
        collar = self._point_marker(drawing)
        if collar is not None:  # outside the link cylinder: visible, unlike a point inside
            markers["point"] = scene.add_line_segments(f"{name}/point", collar, POINT_COLOR,
                                                       thickness=0.004)
        else:
            markers["point"] = scene.add_icosphere(f"{name}/point", 0.008, POINT_COLOR,
                                                   position=geometry.point)
        markers["error"] = scene.add_line_segments(f"{name}/error", np.zeros((1, 2, 3)),
                                                   ERROR_COLOR, thickness=0.003)
        if geometry.allowed_side is not None:
            markers["arrow"] = scene.add_line_segments(
                f"{name}/arrow", arrow_segments(geometry.anchor, geometry.allowed_side,
                                                ALLOWED_SIDE_ARROW),
                geometry.color, thickness=0.004)
        if self.labelled:
            markers["label"] = scene.add_label(
                f"{name}/label", f"{entry_id} on {drawing['link']}",
                position=geometry.anchor + np.array([0.0, 0.0, LABEL_HEIGHT]),
                anchor="bottom-center")
        return markers

    @staticmethod
    def state(drawing: dict) -> np.ndarray:
        """What a constraint's markers are drawn from, as one vector: its geometry's
        points and directions, its link's pose."""
        geometry: ConstraintGeometry = drawing["geometry"]
        placement = drawing["link_placement"]
        parts = [geometry.anchor, geometry.point, geometry.error, placement.translation,
                 placement.rotation]
        parts += [v for v in (geometry.axis, geometry.allowed_side) if v is not None]
        return np.concatenate([np.asarray(part, dtype=float).ravel() for part in parts])

    def _add_shape(self, name: str, drawing: dict) -> Any:
        """The scene node of a constraint's geometry, drawn as its ``shape`` says
        (:data:`web.constraint_drawing.SHAPES`; an unknown shape as a sphere at its anchor)."""
        shape = drawing["geometry"].shape
        add = {"ring": self._add_ring, "plane": self._add_square}.get(shape, self._add_sphere)
        return add(name, drawing)

    def _add_ring(self, name: str, drawing: dict) -> Any:
        """A ring around the link's axis at the anchor, outside the link's meshes."""
        geometry: ConstraintGeometry = drawing["geometry"]
        ring = ring_segments(geometry.anchor, geometry.axis, self.ring_radius_at(drawing))
        return self.server.scene.add_line_segments(f"{name}/{geometry.shape}", ring,
                                                   geometry.color, thickness=0.004)

    def _add_square(self, name: str, drawing: dict) -> Any:
        """A translucent square through the anchor, across the axis, as wide as its link."""
        geometry: ConstraintGeometry = drawing["geometry"]
        size = self.square_sizes.get(drawing["link"], SQUARE_SIZE)
        return self.server.scene.add_box(f"{name}/{geometry.shape}", geometry.color,
                                         (size, size, 0.001), opacity=0.3, side="double",
                                         wxyz=wxyz_from_z(geometry.axis),
                                         position=geometry.anchor)

    def _add_sphere(self, name: str, drawing: dict) -> Any:
        """A translucent sphere at the anchor."""
        geometry: ConstraintGeometry = drawing["geometry"]
        return self.server.scene.add_icosphere(f"{name}/anchor", 0.012, geometry.color,
                                               opacity=0.5, position=geometry.anchor)

    def _along(self, link: str, placement: pin.SE3, point: np.ndarray) -> float:
        """Where the world ``point`` is along ``link``'s axis (link frame, m)."""
        axis = np.asarray(self.robot.link_axes.get(link, (0.0, 0.0, 1.0)), dtype=float)
        return float(placement.actInv(np.asarray(point, dtype=float)) @ axis
                     / np.linalg.norm(axis))

    def ring_radius_at(self, drawing: dict) -> float:
        """Radius of the ring drawn as ``drawing`` (a snapshot's constraint): outside the
        geometry of its link where the ring is (:class:`web.ui.shapes.LinkProfile`)."""
        link, geometry = drawing["link"], drawing["geometry"]
        profile = self.profiles.get(link)
        if profile is None:
            return MIN_RING_RADIUS
        return ring_around(profile.radius_at(
            self._along(link, drawing["link_placement"], geometry.anchor)))

    def collar_radius_at(self, drawing: dict) -> float:
        """Radius of the collar around the link at the constrained point (0: none)."""
        link, geometry = drawing["link"], drawing["geometry"]
        profile = self.profiles.get(link)
        if profile is None or not profile.radial.size:
            return 0.0
        radius = profile.radius_at(self._along(link, drawing["link_placement"], geometry.point))
        return ring_around(radius, minimum=0.0) - 0.001

    def _point_marker(self, drawing: dict) -> np.ndarray | None:
        """The collar around the link at the constrained point (None: draw a sphere)."""
        axis, radius = drawing["link_axis"], self.collar_radius_at(drawing)
        if axis is None or radius <= 0.004:
            return None
        return ring_segments(drawing["geometry"].point, axis, radius, n=24)

    def update(self, markers: dict[str, Any], drawing: dict) -> None:
        """The constraint's nodes moved to ``drawing``."""
        geometry: ConstraintGeometry = drawing["geometry"]
        if geometry.shape == "ring":  # around the link axis, which turns with the link
            markers["shape"].points = ring_segments(geometry.anchor, geometry.axis,
                                                    self.ring_radius_at(drawing))
        else:
            markers["shape"].position = geometry.anchor
        collar = self._point_marker(drawing)
        if collar is not None:
            markers["point"].points = collar
        else:
            markers["point"].position = geometry.point
        # from the point towards where it should be (the error points the other way)
        vector = -ERROR_VECTOR_SCALE * geometry.error
        markers["error"].points = np.array([[geometry.point, geometry.point + vector]])
        markers["error"].visible = float(np.linalg.norm(geometry.error)) > 1e-6
        if "label" in markers:
            markers["label"].position = geometry.anchor + np.array([0.0, 0.0, LABEL_HEIGHT])
        if "arrow" in markers:
            markers["arrow"].points = arrow_segments(geometry.anchor, geometry.allowed_side,
                                                     ALLOWED_SIDE_ARROW)
