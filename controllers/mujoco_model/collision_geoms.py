"""Pinocchio collision geometry as MuJoCo geoms, shape for shape (docs/design.md 18.5).

The mink peer measures its collision pairs with MuJoCo's ``mj_geomDistance`` on its own
model; these geoms make that model's shapes the avoidance's: a capsule, sphere or box is
the same primitive (MuJoCo sizes are half lengths, as coal's ``halfLength`` /
``halfSide``), a convex hull a mesh of its vertices (MuJoCo collides meshes through their
convex hull), a half-space an infinite plane (solid below its local z, as coal's
``Halfspace(z, 0)``). A geometry object's placement is in its parent joint's frame,
which is the frame of MuJoCo's body holding that joint (the world body for joint 0).
"""

from __future__ import annotations

from collections.abc import Mapping

import coal
import mujoco
import numpy as np
import pinocchio as pin

#: Prefix of the MuJoCo geoms added for Pinocchio geometry objects (:func:`geom_name`).
GEOM_PREFIX = "pin:"


def geom_name(geometry_name: str) -> str:
    """Name of the MuJoCo geom added for the Pinocchio geometry object ``geometry_name``."""
    return GEOM_PREFIX + geometry_name


def add_collision_geoms(spec: mujoco.MjSpec, geometry: pin.GeometryModel,
                        bodies: Mapping[int, mujoco.MjsBody]) -> None:
    """Add a geom per object of ``geometry`` to ``spec``, on ``bodies[parentJoint]`` (the
    world body for joint 0), named :func:`geom_name`. They take no part in contacts
    (``contype = conaffinity = 0``) and carry no mass: they are for distances only."""
    for item in geometry.geometryObjects:
        body = spec.worldbody if item.parentJoint == 0 else bodies[item.parentJoint]
        geom = body.add_geom(name=geom_name(item.name), contype=0, conaffinity=0, mass=0.0)
        set_geom_shape(spec, geom, item.geometry, item.name)
        set_geom_pose(geom, item.placement)


def set_geom_pose(geom: mujoco.MjsGeom, placement: pin.SE3) -> None:
    """``geom``'s pose in its body: ``placement``."""
    quaternion = pin.Quaternion(placement.rotation)
    geom.pos = placement.translation.copy()
    geom.quat = [quaternion.w, quaternion.x, quaternion.y, quaternion.z]


def set_geom_shape(spec: mujoco.MjSpec, geom: mujoco.MjsGeom, shape: coal.CollisionGeometry,
                   name: str) -> None:
    """``geom``'s type and size for the coal ``shape`` (``ValueError`` for a shape MuJoCo's
    distance cannot take: a cylinder, which the avoidance turns into a capsule, or a
    non-convex mesh)."""
    if isinstance(shape, coal.Capsule):
        geom.type = mujoco.mjtGeom.mjGEOM_CAPSULE
        geom.size = [shape.radius, shape.halfLength, 0.0]
    elif isinstance(shape, coal.Sphere):
        geom.type = mujoco.mjtGeom.mjGEOM_SPHERE
        geom.size = [shape.radius, 0.0, 0.0]
    elif isinstance(shape, coal.Box):
        geom.type = mujoco.mjtGeom.mjGEOM_BOX
        geom.size = np.asarray(shape.halfSide, dtype=float).copy()
    elif isinstance(shape, coal.Halfspace):
        geom.type = mujoco.mjtGeom.mjGEOM_PLANE
        geom.size = [0.0, 0.0, 1.0]  # infinite
        if not np.allclose(np.asarray(shape.n), (0.0, 0.0, 1.0)) or shape.d != 0.0:
            raise ValueError(f"geometry {name!r}: a half-space must be local z <= 0")
    elif isinstance(shape, coal.ConvexBase):
        mesh = spec.add_mesh(name=geom_name(name))
        mesh.uservert = np.asarray(shape.points(), dtype=float).ravel()
        geom.type = mujoco.mjtGeom.mjGEOM_MESH
        geom.meshname = mesh.name
    else:
        raise ValueError(f"geometry {name!r}: no MuJoCo geom for a {type(shape).__name__} "
                         "(capsules, spheres, boxes, convex hulls and half-spaces)")
