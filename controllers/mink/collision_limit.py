"""The avoidance's pairs through mink's own ``CollisionAvoidanceLimit`` (docs/design.md 18.5).

mink 1.3.0's limit, for a geom pair closer than ``collision_detection_distance`` (``d_i``)
at distance ``d`` (``mj_geomDistance``), holds on the displacement ``dq = v dt``::

    -n^T (J_2 - J_1) dq <= gain (d - d_s) / dt         (0 at or below d_s)

i.e. ``d_dot >= -gain (d - d_s) / dt^2``. The avoidance's damper is
``d_dot >= -k (d - d_s)``, ``k = xi / (d_i - d_s)`` (:attr:`CollisionAvoidance.gain`), so
``gain = k dt^2`` makes the two bounds the same above ``d_s``. What stays mink's: no
obstacle velocity is fed forward, below ``d_s`` the bound is 0 (no push back out), and
the distances and normals are MuJoCo's.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import mink
import mujoco
import numpy as np
import pinocchio as pin
from mink.limits.limit import Constraint as LimitRows

from constraints.collision import CollisionAvoidance, Obstacle
from constraints.collision.geometry import capsule_geometry, link_of

from ..mujoco_model import geom_name

#: Prefix of an obstacle's geometry object (its MuJoCo geom is :func:`geom_name` of it).
OBSTACLE_PREFIX = "obstacle:"


class CollisionPairsLimit(mink.CollisionAvoidanceLimit):
    """mink's collision limit on exactly the geom pairs given, each row named.

    mink's constructor drops pairs on one weld, parent and child bodies and pairs failing
    the contype/conaffinity test; the avoidance already chose its pairs, so every one is
    passed as it is. :attr:`last` keeps the rows of the last evaluation (for the step's
    report); ``held_bound`` (None: none) raises their right-hand side to the least
    residual's (:mod:`controllers.optimization.least_residual`).
    """

    def __init__(self, model: mujoco.MjModel, pairs: Sequence[tuple[int, int]],
                 names: Sequence[str], gain: float, safety_distance: float,
                 detection_distance: float) -> None:
        self._given_pairs = [(int(first), int(second)) for first, second in pairs]
        #: each row's pair, named as the avoidance names it ("first | second")
        self.names = tuple(names)
        super().__init__(model, [], gain=gain,
                         minimum_distance_from_collisions=safety_distance,
                         collision_detection_distance=detection_distance)
        self.last: LimitRows | None = None
        self.held_bound: np.ndarray | None = None
        #: ``braking(G, h, q_mj)``: the bounds made braking-aware with acceleration limits
        #: (the controller's, docs/design.md 12), or None: mink's
        self.braking: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None = None

    def _construct_geom_id_pairs(self, geom_pairs) -> list[tuple[int, int]]:
        return list(self._given_pairs)

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float
                                ) -> LimitRows:
        rows = super().compute_qp_inequalities(configuration, dt)
        if self.braking is not None and rows.G is not None:
            rows = LimitRows(G=rows.G, h=self.braking(rows.G, rows.h, configuration.q))
        if self.held_bound is not None:
            rows = LimitRows(G=rows.G, h=np.maximum(rows.h, self.held_bound))
        self.last = rows
        return rows


class CollisionScene:
    """The avoidance's shapes in mink's MuJoCo model, and its pairs as a
    :class:`CollisionPairsLimit`.

    :meth:`geometry` is the robot's capsule geometry (``capsule_geometry``, as the
    avoidance builds it) and one world object per obstacle at its current pose; the
    controller compiles it into its model. :meth:`place_obstacles` writes the obstacles'
    poses into the compiled model before each step (``geom_pos``, ``geom_quat``);
    :meth:`changed` says when the obstacles' set or shapes differ from the compiled ones
    (the model is then rebuilt).
    """

    def __init__(self, collisions: CollisionAvoidance, collision_model: pin.GeometryModel,
                 model: pin.Model) -> None:
        self.collisions = collisions
        self.model = model
        self.robot_geometry = capsule_geometry(collision_model)
        self._compiled = self._signature()
        self._obstacle_geoms = np.zeros(0, dtype=int)

    def _signature(self) -> tuple:
        """What the compiled model depends on: each obstacle's name, kind and dimensions."""
        return tuple((o.name, o.kind, repr(o.dimensions())) for o in self.collisions.obstacles)

    def changed(self) -> bool:
        return self._signature() != self._compiled

    def geometry(self) -> pin.GeometryModel:
        """The robot's capsule geometry and the obstacles (joint 0, their world pose)."""
        self._compiled = self._signature()
        geometry = self.robot_geometry.copy()
        for obstacle in self.collisions.obstacles:
            geometry.addGeometryObject(pin.GeometryObject(
                OBSTACLE_PREFIX + obstacle.name, 0, 0, obstacle.pose(), obstacle.shape()))
        return geometry

    def limit(self, mj_model: mujoco.MjModel, dt: float) -> CollisionPairsLimit:
        """The pairs of :attr:`CollisionAvoidance.pairs` on ``mj_model`` (compiled from
        :meth:`geometry`): a pair of links is every geom of the first with every geom of
        the second, a pair with an obstacle every geom of the link with the obstacle's."""
        geoms: dict[str, list[int]] = {}
        for item in self.robot_geometry.geometryObjects:
            geoms.setdefault(link_of(self.model, item), []).append(
                mj_model.geom(geom_name(item.name)).id)
        obstacles = self.collisions.obstacles
        self._obstacle_geoms = np.array(
            [mj_model.geom(geom_name(OBSTACLE_PREFIX + o.name)).id for o in obstacles], dtype=int)
        for obstacle, geom in zip(obstacles, self._obstacle_geoms.tolist()):
            geoms[obstacle.name] = [geom]
        pairs, names = [], []
        for first, second in dict.fromkeys(self.collisions.pairs):
            for a in geoms[first]:
                for b in geoms[second]:
                    pairs.append((a, b))
                    names.append(f"{first} | {second}")
        collisions = self.collisions
        return CollisionPairsLimit(mj_model, pairs, names, gain=collisions.gain * dt**2,
                                   safety_distance=collisions.safety_distance,
                                   detection_distance=collisions.detection_distance)

    def place_obstacles(self, mj_model: mujoco.MjModel) -> None:
        """Write each obstacle's world pose into its geom (before the step's kinematics)."""
        for obstacle, geom in zip(self.collisions.obstacles, self._obstacle_geoms.tolist()):
            place(mj_model, geom, obstacle)


def place(mj_model: mujoco.MjModel, geom: int, obstacle: Obstacle) -> None:
    """``geom`` (a world-body geom) at ``obstacle``'s pose."""
    pose = obstacle.pose()
    quaternion = pin.Quaternion(pose.rotation)
    mj_model.geom_pos[geom] = pose.translation
    mj_model.geom_quat[geom] = (quaternion.w, quaternion.x, quaternion.y, quaternion.z)
