"""A MuJoCo model of a robot's URDF and the map between its coordinates and Pinocchio's.

Below every user in the layers: the mink peer (:mod:`controllers.mink`) imports it, and
so may a MuJoCo physics plant in ``teleop``; it imports neither mink nor any controller.

* :func:`build_mujoco_model` - ``(mujoco.MjModel, JointMap)`` from a Pinocchio model and
  its URDF, with a site (:func:`site_name`) at each frame asked for; :func:`mujoco_spec`
  the same spec before compiling, :func:`joint_map` the map of a model compiled from it;
* :mod:`.collision_geoms` - a Pinocchio ``GeometryModel`` as geoms for distances
  (:func:`geom_name`), for the mink peer's collision limit;
* :class:`JointMap`, :class:`PlanarBase` - configurations, velocities and Jacobian columns
  from one model's coordinates to the other's.
"""

from .builder import (
    PLANAR_SUFFIXES,
    SITE_PREFIX,
    build_mujoco_model,
    joint_map,
    mujoco_spec,
    site_name,
)
from .collision_geoms import GEOM_PREFIX, geom_name
from .joint_map import JointMap, PlanarBase

__all__ = ["GEOM_PREFIX", "PLANAR_SUFFIXES", "SITE_PREFIX", "JointMap", "PlanarBase",
           "build_mujoco_model", "geom_name", "joint_map", "mujoco_spec", "site_name"]
