"""Collision avoidance in the 3D scene (docs/design.md section 18): each pair of the main
robot closer than the detection distance drawn highlighted: its links' collision
geometry in a see-through colour and the witness segment between the two witness points,
coloured by the distance (red at the safety distance, yellow at the detection distance).
The obstacles are placed items (:mod:`web.ui.obstacle_drawer`).

The pairs come from the rows the main controller computed for its last step
(``snapshot["robots"]["main"]["collision_rows"]``, an immutable
:class:`constraints.collision.CollisionRows`); the view never measures.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pinocchio as pin
import viser

from constraints.collision import CollisionRows
from constraints.collision.geometry import capsule_geometry, link_of
from teleop.robots import Robot

from .placed_markers import node_name
from .shapes import shape_mesh, wxyz_of

#: the witness segment's and highlight's colour at the safety distance and at the
#: detection distance (linear in between)
NEAR_COLOR = (230, 20, 20)
FAR_COLOR = (245, 200, 0)
#: a highlight's colour changes in this many steps between the two (fewer messages)
COLOR_STEPS = 16
HIGHLIGHT_OPACITY = 0.45
WITNESS_RADIUS = 0.004  # m: the spheres at the witness points


def distance_color(distance: float, safety: float, detection: float) -> tuple[int, int, int]:
    """The colour of a pair at ``distance`` (m): :data:`NEAR_COLOR` at or below the safety
    distance, :data:`FAR_COLOR` at the detection distance and beyond, linear in between
    (in :data:`COLOR_STEPS` steps)."""
    fraction = float(np.clip((distance - safety) / (detection - safety), 0.0, 1.0))
    fraction = round(fraction * COLOR_STEPS) / COLOR_STEPS
    red, green, blue = (int(round(near + fraction * (far - near)))
                        for near, far in zip(NEAR_COLOR, FAR_COLOR))
    return red, green, blue


class PairHighlights:
    """The main robot's pairs near each other, a component of :class:`web.ui.TeleopUI`
    owning its nodes: :attr:`pair_nodes` (pair name -> its witness segment and points),
    :attr:`link_nodes` (link -> its highlight meshes, one per collision geometry of
    ``robot``'s, as the avoidance measures them)."""

    def __init__(self, server: viser.ViserServer, robot: Robot) -> None:
        self.server = server
        self.robot = robot
        self.pair_nodes: dict[str, dict[str, Any]] = {}
        self.link_nodes: dict[str, list[viser.MeshHandle]] = {}
        self._link_colors: dict[str, tuple[int, int, int]] = {}
        #: per link: (joint, placement in the joint's frame, vertices, faces) of each of
        #: its collision geometries, as the avoidance measures them
        self._link_shapes: dict[str, list[tuple[int, pin.SE3, np.ndarray, np.ndarray]]] = {}
        for item in capsule_geometry(robot.collision_model).geometryObjects:
            vertices, faces = shape_mesh(item.geometry)
            self._link_shapes.setdefault(link_of(robot.model, item), []).append(
                (item.parentJoint, item.placement.copy(), vertices, faces))
        self._highlight_data = robot.model.createData()  # the view thread's

    def draw(self, rows: CollisionRows | None, q: np.ndarray, collisions: dict) -> None:
        """The main robot's pairs closer than the detection distance (``rows``: the last
        measured; None: none): per pair the witness segment and points (of its closest
        geometries, when its links have several), per link in a pair its collision
        geometry, coloured by the distance."""
        safety, detection = collisions["safety_distance"], collisions["detection_distance"]
        pairs: dict[str, tuple[float, np.ndarray]] = {}  # a pair's closest geometries
        for name, distance, witness in ([] if rows is None else
                                        zip(rows.pairs, rows.distances, rows.witnesses)):
            if name not in pairs or distance < pairs[name][0]:
                pairs[name] = (float(distance), witness)
        for name in list(self.pair_nodes):
            if name not in pairs:
                for handle in self.pair_nodes.pop(name).values():
                    handle.remove()
        links: dict[str, float] = {}
        for name, (distance, witness) in pairs.items():
            color = distance_color(distance, safety, detection)
            nodes = self.pair_nodes.get(name)
            if nodes is None:
                nodes = self.pair_nodes[name] = self._add_pair(name, witness, color)
            nodes["witness"].points = np.array([witness])
            nodes["witness"].colors = np.tile(np.array(color, dtype=np.uint8), (1, 2, 1))
            for index in range(2):
                nodes[f"point{index}"].position = witness[index]
                nodes[f"point{index}"].color = color
            for link in name.split(" | "):
                if link in self._link_shapes:
                    links[link] = min(distance, links.get(link, np.inf))
        self._highlight_links(links, q, safety, detection)

    def _add_pair(self, name: str, witness: np.ndarray,
                  color: tuple[int, int, int]) -> dict[str, Any]:
        """A pair's witness segment and its two witness points."""
        scene, node = self.server.scene, f"/collisions/pairs/{node_name(name)}"
        nodes: dict[str, Any] = {"witness": scene.add_line_segments(f"{node}/witness", np.array([witness]),
                                                    color, thickness=5.0,
                                                    thickness_units="screen")}
        for index in range(2):
            nodes[f"point{index}"] = scene.add_icosphere(f"{node}/point{index}", WITNESS_RADIUS,
                                                         color, position=witness[index])
        return nodes

    def _highlight_links(self, links: dict[str, float], q: np.ndarray, safety: float,
                         detection: float) -> None:
        """Each link of ``links`` (name -> its closest pair's distance) drawn in its
        colour over its meshes; the others' highlights removed."""
        for link in list(self.link_nodes):
            if link not in links:
                for handle in self.link_nodes.pop(link):
                    handle.remove()
                self._link_colors.pop(link, None)
        if not links:
            return
        model, data = self.robot.model, self._highlight_data
        pin.forwardKinematics(model, data, q)
        for link, distance in links.items():
            color = distance_color(distance, safety, detection)
            shapes = self._link_shapes[link]
            handles = self.link_nodes.get(link)
            if handles is None:
                handles = self.link_nodes[link] = [
                    self.server.scene.add_mesh_simple(
                        f"/collisions/links/{node_name(link)}/{k}", vertices, faces,
                        color=color, opacity=HIGHLIGHT_OPACITY)
                    for k, (_, _, vertices, faces) in enumerate(shapes)]
                self._link_colors[link] = color
            elif self._link_colors.get(link) != color:
                for handle in handles:
                    handle.color = color
                self._link_colors[link] = color
            for handle, (joint, placement, _, _) in zip(handles, shapes):
                pose = data.oMi[joint] * placement
                handle.position = pose.translation
                handle.wxyz = wxyz_of(pose.rotation)
