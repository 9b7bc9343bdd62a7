"""Drawing a robot in viser from any URDF, never failing on its meshes.

:class:`RobotView` is Pinocchio's ``ViserVisualizer`` with fallbacks. A mesh is read with
trimesh (``.dae`` through pycollada, ``.stl``, ``.obj``, with their materials); when that
fails, the triangles Pinocchio itself read (through coal/assimp) are drawn in one colour;
when there are none, a small sphere at the geometry's place. A robot whose visual geometry
could not be loaded at all is drawn with its collision geometry, and one with neither
with a skeleton of primitives (a sphere per joint, a cylinder per link). Each fallback is
a line in :attr:`RobotView.problems` (the UI shows them as a notification): never a crash.
"""

from __future__ import annotations

from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import trimesh
import viser
from pinocchio.visualize import ViserVisualizer

from teleop.robots import Robot

SKELETON_COLOR = np.array([0.55, 0.58, 0.62, 1.0])
#: a configuration (rad, m) or mesh pose (m, quaternion) that moved less than this since it
#: was last sent is not sent again: invisible, and a physics plant's robot is never
#: bit-for-bit still (each mesh pose sent costs the view thread, which shares the
#: interpreter with the 1 kHz control loop, about 0.1 ms)
DISPLAY_RESOLUTION = 1e-7


def skeleton_geometry(model: pin.Model, radius: float = 0.02) -> pin.GeometryModel:
    """Primitive geometry for a model without any: a sphere at each joint, a cylinder
    from each joint to its child."""
    geometry = pin.GeometryModel()
    for joint in range(1, model.njoints):
        parent = model.parents[joint]
        sphere = pin.GeometryObject(f"skeleton_joint_{model.names[joint]}", joint,
                                    pin.SE3.Identity(), coal.Sphere(1.5 * radius))
        sphere.meshColor = SKELETON_COLOR
        geometry.addGeometryObject(sphere)
        offset = np.asarray(model.jointPlacements[joint].translation)
        length = float(np.linalg.norm(offset))
        if length < 1e-6:
            continue
        rotation = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), offset / length)
        placement = pin.SE3(rotation.matrix(), 0.5 * offset)
        link = pin.GeometryObject(f"skeleton_link_{model.names[joint]}", parent, placement,
                                  coal.Cylinder(radius, length))
        link.meshColor = SKELETON_COLOR
        geometry.addGeometryObject(link)
    return geometry


def floor_height(robot: Robot) -> float:
    """Height (m) of the floor under the robot: the bottom of its base at home (the
    geometry fixed to the world, or carried by a planar root joint, which moves on the
    floor), else the base frame's origin."""
    base_joints = (0, 1) if robot.root_joint == "planar" else (0,)
    bottoms = []
    for geometry_object in robot.visual_model.geometryObjects:
        if geometry_object.parentJoint not in base_joints:
            continue
        shape = geometry_object.geometry
        try:
            shape.computeLocalAABB()
            low, high = np.asarray(shape.aabb_local.min_), np.asarray(shape.aabb_local.max_)
        except (AttributeError, RuntimeError):
            continue
        corners = np.array([[x, y, z] for x in (low[0], high[0]) for y in (low[1], high[1])
                            for z in (low[2], high[2])])
        scale = np.asarray(geometry_object.meshScale) if isinstance(shape, coal.BVHModelBase) else 1.0
        placement = geometry_object.placement
        world = (corners * scale) @ placement.rotation.T + placement.translation
        bottoms.append(float(world[:, 2].min()))
    return min(bottoms) if bottoms else 0.0


def _coal_mesh(shape) -> tuple[np.ndarray, np.ndarray] | None:
    """Vertices and triangles Pinocchio read into a coal mesh, or None."""
    if not isinstance(shape, coal.BVHModelBase) or shape.num_tris == 0:
        return None
    vertices = np.asarray(shape.vertices(), dtype=np.float32)
    faces = np.array([[shape.tri_indices(i)[k] for k in range(3)]
                      for i in range(shape.num_tris)], dtype=np.uint32)
    return vertices, faces


class RobotView(ViserVisualizer):
    """Pinocchio's viser visualiser that draws what it can and says what it could not.

    Parameters
    ----------
    robot : the robot.
    server : the viser server (never a new one: the visualiser would bind 0.0.0.0).
    root : scene node the robot is drawn under.
    color : RGBA (0-1) for every geometry (a ghost), or None for the URDF's own colours.
    """

    def __init__(self, robot: Robot, server: viser.ViserServer, root: str,
                 color: tuple[float, float, float, float] | None = None) -> None:
        self.problems: list[str] = []
        self.color = color
        self._shown: np.ndarray | None = None  # the configuration last displayed
        self._sent: dict[str, np.ndarray] = {}  # each mesh's pose last sent (xyz, wxyz)
        visual = robot.visual_model
        if len(visual.geometryObjects) == 0:
            if len(robot.collision_model.geometryObjects) > 0:
                self.problems.append("no visual geometry could be loaded: drawing the "
                                     "collision geometry")
                visual = robot.collision_model
            else:
                self.problems.append("no geometry could be loaded: drawing a skeleton")
                visual = skeleton_geometry(robot.model)
        super().__init__(robot.model, robot.collision_model, visual)
        self.initViewer(viewer=server)
        self.loadViewerModel(rootNodeName=root, visual_color=None if color is None else list(color))
        self.displayCollisions(False)
        self.displayFrames(False)

    def display(self, q=None):
        """Place the robot at ``q``; nothing to do (nor send) when it has not moved by
        :data:`DISPLAY_RESOLUTION` since it was last shown."""
        if q is not None:
            q = np.asarray(q, dtype=float)
            if self._shown is not None and q.shape == self._shown.shape and \
                    float(np.max(np.abs(q - self._shown), initial=0.0)) < DISPLAY_RESOLUTION:
                return
            self._shown = q.copy()
        super().display(q)

    def loadViewerModel(self, rootNodeName="pinocchio", collision_color=None, visual_color=None,
                        frame_axis_length=0.2, frame_axis_radius=0.01):
        # the collision geometry is never shown: not loading it halves the meshes sent
        collision, self.collision_model = self.collision_model, pin.GeometryModel()
        try:
            super().loadViewerModel(rootNodeName, collision_color, visual_color,
                                    frame_axis_length, frame_axis_radius)
        finally:
            self.collision_model = collision
            self.collision_data = collision.createData()

    def updatePlacements(self, geometry_type):
        """Send the pose of each visual mesh that moved by :data:`DISPLAY_RESOLUTION` (a
        dragged arm's links, not the torso's nor the other arm's)."""
        if geometry_type == pin.GeometryType.COLLISION:
            return  # not drawn (see loadViewerModel)
        pin.updateGeometryPlacements(self.model, self.data, self.visual_model, self.visual_data)
        prefix = self.viewerRootNodeName + "/visual"
        for placement, geometry_object in zip(self.visual_data.oMg,
                                              self.visual_model.geometryObjects):
            name = f"{prefix}/{geometry_object.name}"
            x, y, z, w = pin.Quaternion(placement.rotation).coeffs()
            pose = np.array([*placement.translation, w, x, y, z])
            sent = self._sent.get(name)
            if sent is not None and float(np.max(np.abs(pose - sent))) < DISPLAY_RESOLUTION:
                continue
            self._sent[name] = pose
            frame = self.frames[name]
            frame.position = pose[:3]
            frame.wxyz = pose[3:]

    def loadViewerGeometryObject(self, geometry_object, prefix="", color=None):
        try:
            super().loadViewerGeometryObject(geometry_object, prefix, color)
        except Exception as error:  # a mesh reader can raise anything: draw what we can
            name = f"{prefix}/{geometry_object.name}" if prefix else geometry_object.name
            reason = " ".join(str(error).split()) or type(error).__name__
            self.frames[name] = self._fallback(name, geometry_object, color, reason)

    def _fallback(self, name: str, geometry_object, color, reason: str):
        scene = self.viewer.scene
        rgba = np.asarray(color if color is not None else geometry_object.meshColor, dtype=float)
        rgb = tuple(int(255 * c) for c in rgba[:3])
        file = Path(geometry_object.meshPath).name or geometry_object.name
        mesh = _coal_mesh(geometry_object.geometry)
        if mesh is not None:
            self.problems.append(f"{file}: {reason}; drawn from the mesh Pinocchio read, "
                                 "without its materials")
            vertices, faces = mesh
            return scene.add_mesh_simple(name, vertices * np.asarray(geometry_object.meshScale),
                                         faces, color=rgb, opacity=float(rgba[3]))
        self.problems.append(f"{file}: {reason}; drawn as a sphere")
        return scene.add_icosphere(name, radius=0.03, color=rgb, opacity=float(rgba[3]))

    def _add_mesh_from_path(self, name, mesh_path, color, scale):
        if self.color is not None and Path(mesh_path).suffix.lower() == ".dae":
            # the base class would drop the colour of a .dae (a ghost would look like the robot)
            mesh = trimesh.load_scene(mesh_path).to_geometry()
            mesh.apply_scale(scale)
            return self.viewer.scene.add_mesh_simple(
                name, mesh.vertices, mesh.faces, color=tuple(float(c) for c in self.color[:3]),
                opacity=float(self.color[3]))
        return super()._add_mesh_from_path(name, mesh_path, color, scale)
