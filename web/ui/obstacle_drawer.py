"""Each obstacle drawn from its own ``geometry()`` (docs/design.md section 18): a sphere,
a box, a capsule, a half-space (or a shape this view does not know) as a large thin
square with an arrow to its free side. An obstacle is a placed item: its gizmo, its
redrawing and its removal are :class:`web.ui.placed_markers.PlacedMarkers`'."""

from __future__ import annotations

from typing import Any

import coal
import numpy as np
import viser

from constraints.collision import ObstacleGeometry

from .shapes import arrow_segments, shape_mesh, wxyz_of

OBSTACLE_OPACITY = 0.55
#: a half-space is drawn as a square this wide (m), its free side by an arrow this long
HALFSPACE_SIZE = 1.2
HALFSPACE_ARROW = 0.1


def dimension(geometry: ObstacleGeometry, name: str) -> np.ndarray:
    """One of an obstacle's dimensions (m) as an array (a radius, a length, the edges)."""
    return np.asarray(geometry.dimensions[name], dtype=float)


def halfspace_arrow(geometry: ObstacleGeometry) -> np.ndarray:
    """The arrow from a half-space's boundary to its free side (along its normal)."""
    return arrow_segments(geometry.center, geometry.rotation[:, 2], HALFSPACE_ARROW)


class ObstacleDrawer:
    """The scene nodes of an obstacle (an :class:`web.ui.placed_markers.ItemDrawer`) from
    its drawing (a snapshot's obstacle, its ``"geometry"``): ``"shape"`` and, on a
    half-space, ``"arrow"``."""

    def __init__(self, server: viser.ViserServer) -> None:
        self.server = server

    def create(self, name: str, entry_id: str, drawing: dict) -> dict[str, Any]:
        """The obstacle's nodes under ``name``, as its geometry's shape says."""
        geometry: ObstacleGeometry = drawing["geometry"]
        pose = {"position": geometry.center, "wxyz": wxyz_of(geometry.rotation)}
        add = {"sphere": self._add_sphere, "box": self._add_box,
               "capsule": self._add_capsule}.get(geometry.shape, self._add_halfspace)
        return add(name, geometry, pose)

    @staticmethod
    def state(drawing: dict) -> np.ndarray:
        """What an obstacle's nodes are drawn from: its centre and rotation."""
        geometry: ObstacleGeometry = drawing["geometry"]
        return np.concatenate([geometry.center, geometry.rotation.ravel()])

    @staticmethod
    def update(nodes: dict[str, Any], drawing: dict) -> None:
        """The obstacle's nodes moved to its geometry."""
        geometry: ObstacleGeometry = drawing["geometry"]
        nodes["shape"].position = geometry.center
        nodes["shape"].wxyz = wxyz_of(geometry.rotation)
        if "arrow" in nodes:
            nodes["arrow"].points = halfspace_arrow(geometry)

    def _add_sphere(self, name: str, geometry: ObstacleGeometry, pose: dict) -> dict[str, Any]:
        return {"shape": self.server.scene.add_icosphere(
            f"{name}/shape", float(dimension(geometry, "radius")), geometry.color,
            opacity=OBSTACLE_OPACITY, **pose)}

    def _add_box(self, name: str, geometry: ObstacleGeometry, pose: dict) -> dict[str, Any]:
        return {"shape": self.server.scene.add_box(
            f"{name}/shape", geometry.color, dimension(geometry, "edges"),
            opacity=OBSTACLE_OPACITY, **pose)}

    def _add_capsule(self, name: str, geometry: ObstacleGeometry, pose: dict) -> dict[str, Any]:
        vertices, faces = shape_mesh(coal.Capsule(float(dimension(geometry, "radius")),
                                                  float(dimension(geometry, "length"))))
        return {"shape": self.server.scene.add_mesh_simple(
            f"{name}/shape", vertices, faces, color=geometry.color, opacity=OBSTACLE_OPACITY,
            **pose)}

    def _add_halfspace(self, name: str, geometry: ObstacleGeometry,
                       pose: dict) -> dict[str, Any]:
        """A half-space (or a shape this view does not know): its boundary as a large thin
        square, an arrow to the free side."""
        scene = self.server.scene
        return {"shape": scene.add_box(f"{name}/shape", geometry.color,
                                       (HALFSPACE_SIZE, HALFSPACE_SIZE, 0.002), opacity=0.3,
                                       side="double", **pose),
                "arrow": scene.add_line_segments(f"{name}/arrow", halfspace_arrow(geometry),
                                                 geometry.color, thickness=0.004)}
