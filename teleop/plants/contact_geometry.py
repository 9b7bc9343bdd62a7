"""The physics plant's collision geometry (docs/design.md section 18.6): the robot's capsule
geometry and the obstacles of a collision avoidance as MuJoCo geoms, in contact exactly in
the avoidance's pairs.

Every geom has ``contype = conaffinity = 0`` and each pair of the avoidance (robot-robot
between non-adjacent links, robot-obstacle) is an explicit MuJoCo contact pair, so
``data.contact`` holds the simulated robot's contacts in those pairs and no other. The
pairs are compiled with the avoidance's pairs when the plant is built; a port added later
switches off the pairs it exempts (:mod:`teleop.plants.contact_pairs`).
"""

from __future__ import annotations

import coal
import mujoco
import numpy as np
import pinocchio as pin

from constraints.collision import CollisionAvoidance, Obstacle
from constraints.collision.geometry import capsule_geometry, link_of

from controllers.mujoco_model.builder import PLANAR_SUFFIXES

#: Prefixes of the geoms' names: the robot's (then the geometry's name) and the obstacles'.
ROBOT_GEOM, OBSTACLE_GEOM = "collision:", "obstacle:"

#: Two small spheres a metre apart, far below the world, in no pair of their own (every
#: other geom has ``conaffinity = 0``): a contact pair switched off points at them
#: (:mod:`teleop.plants.contact_pairs`).
PARKING_GEOMS = ("parking:first", "parking:second")
PARKING_HEIGHTS = (-100.0, -101.0)
PARKING_RADIUS = 1e-3


def _quaternion(rotation: np.ndarray) -> list[float]:
    quaternion = pin.Quaternion(rotation)
    return [quaternion.w, quaternion.x, quaternion.y, quaternion.z]


def _set_shape(spec: mujoco.MjSpec, geom: mujoco.MjsGeom, shape: coal.CollisionGeometry,
               name: str) -> None:
    """Give ``geom`` the type and size of the coal ``shape`` (``ValueError`` otherwise)."""
    if isinstance(shape, coal.Sphere):
        geom.type, geom.size = mujoco.mjtGeom.mjGEOM_SPHERE, [shape.radius, 0.0, 0.0]
    elif isinstance(shape, coal.Capsule):
        geom.type = mujoco.mjtGeom.mjGEOM_CAPSULE
        geom.size = [shape.radius, shape.halfLength, 0.0]
    elif isinstance(shape, coal.Box):
        geom.type, geom.size = mujoco.mjtGeom.mjGEOM_BOX, list(shape.halfSide)
    elif isinstance(shape, coal.Halfspace):
        geom.type, geom.size = mujoco.mjtGeom.mjGEOM_PLANE, [0.0, 0.0, 1.0]
    elif isinstance(shape, coal.ConvexBase):
        points = np.array([shape.points(i) for i in range(shape.num_points)], dtype=float)
        spec.add_mesh(name=f"hull:{name}", uservert=points.ravel().tolist())
        geom.type, geom.meshname = mujoco.mjtGeom.mjGEOM_MESH, f"hull:{name}"
    else:
        raise ValueError(f"collision geometry {name!r}: the physics plant cannot simulate a "
                         f"{type(shape).__name__}")


def _body(spec: mujoco.MjSpec, model: pin.Model, joint: int) -> mujoco.MjsBody:
    """The MuJoCo body moved by Pinocchio's ``joint`` (the world body for joint 0)."""
    if joint == 0:
        return spec.worldbody
    name = model.names[joint]
    found = spec.joint(name) or spec.joint(name + PLANAR_SUFFIXES[0])
    if found is None:
        raise ValueError(f"joint {name!r} has no MuJoCo body to carry its collision geometry")
    return found.parent


def add_contact_geometry(spec: mujoco.MjSpec, robot, collisions: CollisionAvoidance
                         ) -> dict[frozenset[str], tuple[str, str]]:
    """Add the robot's collision geometry, ``collisions``' obstacles (world geoms), the
    avoidance's pairs as explicit contact pairs and the two :data:`PARKING_GEOMS` to
    ``spec`` (before it compiles); returns the avoidance's pair (the names of its links or
    obstacles, as ``CollisionAvoidance.pairs`` gives them) by its contact pair's geom
    names."""
    model = robot.model
    geoms: dict[str, list[str]] = {}  # link or obstacle name -> its geoms
    for item in capsule_geometry(robot.collision_model).geometryObjects:
        name = ROBOT_GEOM + item.name
        geom = _body(spec, model, item.parentJoint).add_geom(
            name=name, pos=item.placement.translation.copy(),
            quat=_quaternion(item.placement.rotation), contype=0, conaffinity=0)
        _set_shape(spec, geom, item.geometry, item.name)
        geoms.setdefault(link_of(model, item), []).append(name)
    for obstacle in collisions.obstacles:
        add_obstacle(spec, obstacle)
        geoms[obstacle.name] = [OBSTACLE_GEOM + obstacle.name]
    pairs = {(first, second): (a, b) for a, b in collisions.pairs
             for first in geoms[a] for second in geoms[b]}
    for first, second in sorted(pairs):
        spec.add_pair(geomname1=first, geomname2=second)
    for name, height in zip(PARKING_GEOMS, PARKING_HEIGHTS):
        spec.worldbody.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_SPHERE,
                                size=[PARKING_RADIUS, 0.0, 0.0], pos=[0.0, 0.0, height],
                                contype=1, conaffinity=0)  # kept (not visual), in no pair
    return {frozenset(key): names for key, names in pairs.items()}


def add_obstacle(spec: mujoco.MjSpec, obstacle: Obstacle) -> None:
    """``obstacle`` as a world geom at its pose (it does not move in the simulation)."""
    pose = obstacle.pose()
    geom = spec.worldbody.add_geom(name=OBSTACLE_GEOM + obstacle.name,
                                   pos=pose.translation.copy(),
                                   quat=_quaternion(pose.rotation), contype=0, conaffinity=0)
    _set_shape(spec, geom, obstacle.shape(), obstacle.name)
