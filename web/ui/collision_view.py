"""Collision avoidance in the 3D scene (docs/design.md section 18): each obstacle drawn
from its own ``geometry()`` (a sphere, a box, a capsule, a half-space as a large thin
square with an arrow to its free side) with a gizmo that moves it; each pair of the main
robot closer than the detection distance drawn highlighted: its links' collision
geometry in a see-through colour and the witness segment between the two witness points,
coloured by the distance (red at the safety distance, yellow at the detection distance).

The pairs come from the rows the main controller computed for its last step
(``snapshot["robots"]["main"]["collision_rows"]``, an immutable
:class:`constraints.collision.CollisionRows`); the view never measures.
"""

from __future__ import annotations

import re

import coal
import numpy as np
import pinocchio as pin
import viser

from constraints.collision import CollisionRows, ObstacleGeometry
from constraints.collision.geometry import capsule_geometry, link_of

from ..app import TeleopApp
from .shapes import arrow_segments, shape_mesh, wxyz_of

#: the witness segment's and highlight's colour at the safety distance and at the
#: detection distance (linear in between)
NEAR_COLOR = (230, 20, 20)
FAR_COLOR = (245, 200, 0)
#: a highlight's colour changes in this many steps between the two (fewer messages)
COLOR_STEPS = 16
HIGHLIGHT_OPACITY = 0.45
OBSTACLE_OPACITY = 0.55
#: a half-space is drawn as a square this wide (m), its free side by an arrow this long
HALFSPACE_SIZE = 1.2
HALFSPACE_ARROW = 0.1
WITNESS_RADIUS = 0.004  # m: the spheres at the witness points


def distance_color(distance: float, safety: float, detection: float) -> tuple[int, int, int]:
    """The colour of a pair at ``distance`` (m): :data:`NEAR_COLOR` at or below the safety
    distance, :data:`FAR_COLOR` at the detection distance and beyond, linear in between
    (in :data:`COLOR_STEPS` steps)."""
    fraction = float(np.clip((distance - safety) / (detection - safety), 0.0, 1.0))
    fraction = round(fraction * COLOR_STEPS) / COLOR_STEPS
    return tuple(int(round(near + fraction * (far - near)))
                 for near, far in zip(NEAR_COLOR, FAR_COLOR))


def node_name(name: str) -> str:
    """A link, obstacle or pair name as one scene-node name (no ``/``, no spaces): a pair
    ``"a | b"`` becomes ``"a--b"``."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name.replace(" | ", "--"))


class CollisionView:
    """The obstacles and the highlighted pairs of :class:`web.ui.TeleopUI`
    (``_obstacle_nodes``: obstacle id -> its handles; ``_pair_nodes``: pair name -> its
    witness segment and points; ``_link_nodes``: link -> its highlight meshes)."""

    server: viser.ViserServer
    app: TeleopApp

    def _build_collision_view(self) -> None:
        robot = self.app.robot
        self._obstacle_nodes: dict[str, dict] = {}
        self._obstacle_drawn: dict[str, np.ndarray] = {}
        self._pair_nodes: dict[str, dict] = {}
        self._link_nodes: dict[str, list] = {}
        self._link_colors: dict[str, tuple] = {}
        #: per link: (joint, placement in the joint's frame, vertices, faces) of each of
        #: its collision geometries, as the avoidance measures them
        self._link_shapes: dict[str, list] = {}
        for item in capsule_geometry(robot.collision_model).geometryObjects:
            vertices, faces = shape_mesh(item.geometry)
            self._link_shapes.setdefault(link_of(robot.model, item), []).append(
                (item.parentJoint, item.placement.copy(), vertices, faces))
        self._highlight_data = robot.model.createData()  # the view thread's

    # -- obstacles -----------------------------------------------------------------------------

    def _draw_obstacles(self, obstacles: list[dict]) -> None:
        """``snapshot["collisions"]["obstacles"]``: create, move and remove their nodes."""
        drawn = {entry["id"]: entry for entry in obstacles}
        for entry_id in list(self._obstacle_nodes):
            if entry_id not in drawn:
                for handle in self._obstacle_nodes.pop(entry_id).values():
                    handle.remove()
                self._obstacle_drawn.pop(entry_id, None)
        for entry_id, entry in drawn.items():
            geometry: ObstacleGeometry = entry["geometry"]
            if entry_id not in self._obstacle_nodes:
                self._obstacle_nodes[entry_id] = self._add_obstacle(entry_id, geometry,
                                                                    entry["goal"])
            state = np.concatenate([geometry.center, geometry.rotation.ravel()])
            last = self._obstacle_drawn.get(entry_id)
            if last is None or float(np.max(np.abs(state - last))) > 1e-7:
                nodes = self._obstacle_nodes[entry_id]
                nodes["shape"].position = geometry.center
                nodes["shape"].wxyz = wxyz_of(geometry.rotation)
                if "arrow" in nodes:
                    nodes["arrow"].points = self._halfspace_arrow(geometry)
                self._obstacle_drawn[entry_id] = state
        self.obstacle_panel.show_placed(tuple(drawn))

    def _forget_obstacles(self) -> None:
        """Remove every obstacle's nodes (a loaded scene's are drawn afresh)."""
        for nodes in self._obstacle_nodes.values():
            for handle in nodes.values():
                handle.remove()
        self._obstacle_nodes.clear()
        self._obstacle_drawn.clear()

    def _add_obstacle(self, entry_id: str, geometry: ObstacleGeometry, goal: np.ndarray) -> dict:
        """An obstacle's shape, as its geometry says, and its gizmo."""
        scene, name = self.server.scene, f"/obstacles/{node_name(entry_id)}"
        pose = {"position": geometry.center, "wxyz": wxyz_of(geometry.rotation)}
        add = {"sphere": self._add_sphere_obstacle, "box": self._add_box_obstacle,
               "capsule": self._add_capsule_obstacle}.get(geometry.shape,
                                                          self._add_halfspace_obstacle)
        nodes = add(name, geometry, pose)
        handle = scene.add_transform_controls(f"{name}/gizmo", scale=0.08, position=goal,
                                              disable_rotations=True, depth_test=False)

        @handle.on_update
        def _(event) -> None:
            position = np.array(handle.position)
            self._guarded(event, lambda: self.app.collisions.move(entry_id, position),
                          key=("obstacle", entry_id))

        nodes["gizmo"] = handle
        return nodes

    def _add_sphere_obstacle(self, name: str, geometry: ObstacleGeometry, pose: dict) -> dict:
        return {"shape": self.server.scene.add_icosphere(
            f"{name}/shape", float(geometry.dimensions["radius"]), geometry.color,
            opacity=OBSTACLE_OPACITY, **pose)}

    def _add_box_obstacle(self, name: str, geometry: ObstacleGeometry, pose: dict) -> dict:
        return {"shape": self.server.scene.add_box(
            f"{name}/shape", geometry.color, tuple(geometry.dimensions["edges"]),
            opacity=OBSTACLE_OPACITY, **pose)}

    def _add_capsule_obstacle(self, name: str, geometry: ObstacleGeometry, pose: dict) -> dict:
        vertices, faces = shape_mesh(coal.Capsule(float(geometry.dimensions["radius"]),
                                                  float(geometry.dimensions["length"])))
        return {"shape": self.server.scene.add_mesh_simple(
            f"{name}/shape", vertices, faces, color=geometry.color, opacity=OBSTACLE_OPACITY,
            **pose)}

    def _add_halfspace_obstacle(self, name: str, geometry: ObstacleGeometry, pose: dict) -> dict:
        """A half-space (or a shape this view does not know): its boundary as a large thin
        square, an arrow to the free side."""
        scene = self.server.scene
        return {"shape": scene.add_box(f"{name}/shape", geometry.color,
                                       (HALFSPACE_SIZE, HALFSPACE_SIZE, 0.002), opacity=0.3,
                                       side="double", **pose),
                "arrow": scene.add_line_segments(f"{name}/arrow", self._halfspace_arrow(geometry),
                                                 geometry.color, thickness=0.004)}

    @staticmethod
    def _halfspace_arrow(geometry: ObstacleGeometry) -> np.ndarray:
        return arrow_segments(geometry.center, geometry.rotation[:, 2], HALFSPACE_ARROW)

    # -- the pairs near each other ------------------------------------------------------------

    def _draw_pairs(self, rows: CollisionRows | None, q: np.ndarray, collisions: dict) -> None:
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
        for name in list(self._pair_nodes):
            if name not in pairs:
                for handle in self._pair_nodes.pop(name).values():
                    handle.remove()
        links: dict[str, float] = {}
        for name, (distance, witness) in pairs.items():
            color = distance_color(distance, safety, detection)
            nodes = self._pair_nodes.get(name)
            if nodes is None:
                nodes = self._pair_nodes[name] = self._add_pair(name, witness, color)
            nodes["witness"].points = np.array([witness])
            nodes["witness"].colors = np.tile(np.array(color, dtype=np.uint8), (1, 2, 1))
            for index in range(2):
                nodes[f"point{index}"].position = witness[index]
                nodes[f"point{index}"].color = color
            for link in name.split(" | "):
                if link in self._link_shapes:
                    links[link] = min(distance, links.get(link, np.inf))
        self._highlight_links(links, q, safety, detection)

    def _add_pair(self, name: str, witness: np.ndarray, color: tuple) -> dict:
        scene, node = self.server.scene, f"/collisions/pairs/{node_name(name)}"
        nodes = {"witness": scene.add_line_segments(f"{node}/witness", np.array([witness]),
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
        for link in list(self._link_nodes):
            if link not in links:
                for handle in self._link_nodes.pop(link):
                    handle.remove()
                self._link_colors.pop(link, None)
        if not links:
            return
        model, data = self.app.robot.model, self._highlight_data
        pin.forwardKinematics(model, data, q)
        for link, distance in links.items():
            color = distance_color(distance, safety, detection)
            shapes = self._link_shapes[link]
            handles = self._link_nodes.get(link)
            if handles is None:
                handles = self._link_nodes[link] = [
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
