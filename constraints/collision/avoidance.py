"""Collision avoidance: the pairs kept apart and their velocity-damper rows (docs/design.md 18).

:class:`CollisionAvoidance` holds the robot's capsule geometry, the obstacles, the pairs
to check (self-collision and robot-obstacle) and the damper's three numbers; at each step
:meth:`CollisionAvoidance.rows` measures the pairs a bounding-sphere broadphase lets
through and returns one row per pair closer than the detection distance
(:class:`~constraints.collision.rows.CollisionRows`). The controllers hold the rows as
inequalities: the CJM in its active set after the trocar rows, the QP in its constraints.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any, Protocol

import coal
import numpy as np
import pinocchio as pin

from ..base import cross
from ..kinematics import resolve_frame
from ..limits import (MAX_COLLISION_DISTANCE_M, MAX_OBSTACLES, MAX_RESPONSE_TIME_S,
                      MAX_SPEED_M_S)
from ..validation import as_number, short_repr
from .broadphase import ObstacleBoxes, capsule_boxes
from .geometry import (bounding_segment, capsule_geometry, check_links, link_of, link_pairs,
                       segment_distances, self_collision_pairs, shape_distance)
from .obstacles import Obstacle
from .ports import is_port
from .primitives import CollisionPrimitives, primitive
from .rows import CollisionRows

#: coal's GJK and EPA tolerance on the pairs with a box (coal's default, 1e-6, leaves a
#: box pair's normal 2e-3 rad off: the error of its distance's square root; at 1e-10 the
#: distance, normal and witness points are exact to 1e-9, docs/design.md 18.4)
GJK_TOLERANCE = 1e-10
#: the distance (m) the damper keeps every pair apart, ``d_s``
DEFAULT_SAFETY_DISTANCE = 0.005
#: the distance (m) below which a pair gets its row, ``d_i``
DEFAULT_DETECTION_DISTANCE = 0.05
#: a pair coal measures closer than ``d_i - BOUNDING_MARGIN`` (m) has its bounding capsules
#: within ``d_i`` without their segments measured (the margin above the segment
#: distances' 1e-6 m and coal's GJK tolerance; docs/design.md 18.3)
BOUNDING_MARGIN = 1e-4
#: ``xi`` (m/s): how fast a pair may approach at the detection distance (0 at ``d_s``)
DEFAULT_APPROACH_SPEED = 0.5


class CollisionRobot(Protocol):
    """What collision avoidance needs of a robot (``teleop.Robot`` satisfies it)."""

    @property
    def model(self) -> pin.Model: ...
    @property
    def collision_model(self) -> pin.GeometryModel: ...
    @property
    def q_home(self) -> np.ndarray: ...


class CollisionAvoidance:
    """The pairs of bodies kept at least ``safety_distance`` apart (docs/design.md 18).

    Each pair closer than ``detection_distance`` gets the velocity damper of Faverjon and
    Tournassoud, ``d_dot >= -K (d - d_s)`` (the obstacle's velocity fed forward), a row of
    :class:`CollisionRows`, at the rate ``K = xi / (d_i - d_s)``, or with a robot that
    follows its command ``response_time`` late ``1 / K = (d_i - d_s) / xi + response_time``
    (:attr:`gain`, docs/design.md 18.3). In discrete time at period ``dt`` the damper is
    stable for ``K dt < 1``, which :meth:`check` tests.

    Parameters
    ----------
    robot : the robot (its ``model``, ``collision_model`` and ``q_home``; an optional
        ``collision_disabled``: link pairs never checked, as an SRDF's).
    obstacles : the world's obstacles (:mod:`constraints.collision.obstacles`).
    safety_distance : ``d_s`` (m), >= 0.
    detection_distance : ``d_i`` (m), > ``d_s``.
    approach_speed : ``xi`` (m/s), > 0: the approach speed allowed at ``d_i``.
    self_collision : check the robot's links against each other (else obstacles only).
    disabled_pairs : link pairs added to the robot's disable list.
    extra_pairs : link pairs checked whatever the rules say (adjacent ones included).
    response_time : ``tau`` (s), >= 0: how late the robot follows a command (its servos'
        time constant, :attr:`teleop.plants.PlantChoice.response_time`); the damper takes
        the gap ``tau`` ahead along the command. 0: the robot moves as commanded.
    """

    def __init__(self, robot: CollisionRobot, obstacles: Iterable[Obstacle] = (), *,
                 safety_distance: float = DEFAULT_SAFETY_DISTANCE,
                 detection_distance: float = DEFAULT_DETECTION_DISTANCE,
                 approach_speed: float = DEFAULT_APPROACH_SPEED, self_collision: bool = True,
                 disabled_pairs: Iterable[Sequence[str]] = (),
                 extra_pairs: Iterable[Sequence[str]] = (),
                 response_time: float = 0.0) -> None:
        self._safety_distance = as_number(safety_distance, "safety_distance", 0.0,
                                          maximum=MAX_COLLISION_DISTANCE_M)
        self._detection_distance = as_number(detection_distance, "detection_distance",
                                             maximum=MAX_COLLISION_DISTANCE_M)
        if not self.detection_distance > self.safety_distance:
            raise ValueError(f"detection_distance ({self.detection_distance:g} m) must exceed "
                             f"safety_distance ({self.safety_distance:g} m)")
        self._approach_speed = as_number(approach_speed, "approach_speed", positive=True,
                                         maximum=MAX_SPEED_M_S)
        self._response_time = as_number(response_time, "response_time", 0.0,
                                        maximum=MAX_RESPONSE_TIME_S)
        if not isinstance(self_collision, (bool, np.bool_)):
            raise ValueError(f"self_collision must be true or false, got {short_repr(self_collision)}")
        self.self_collision = bool(self_collision)
        self.model = robot.model
        pairs = {}
        for name, given in (("collision_disabled", getattr(robot, "collision_disabled", ())),
                            ("disabled_pairs", disabled_pairs), ("extra_pairs", extra_pairs)):
            pairs[name] = link_pairs(given, name)
            check_links(self.model, pairs[name], name)
        self.disabled_pairs = [tuple(sorted(key)) for key in pairs["disabled_pairs"]]
        self.extra_pairs = [tuple(sorted(key)) for key in pairs["extra_pairs"]]
        disabled = pairs["collision_disabled"] | pairs["disabled_pairs"]
        extra = pairs["extra_pairs"]
        self._robot_geometry = capsule_geometry(robot.collision_model)
        self._self_pairs = (self_collision_pairs(self.model, self._robot_geometry, robot.q_home,
                                                 self.safety_distance, disabled, extra)
                            if self.self_collision else [])
        self._links = [link_of(self.model, item)
                       for item in self._robot_geometry.geometryObjects]
        self._exempt: set[tuple[int, int]] = set()
        #: counts the rebuilds of the pairs (obstacles added or removed, ports): the
        #: compiled step describes the pairs again when it changes (:meth:`primitives`)
        self.revision = 0
        #: the rows of the last :meth:`rows` call (for views and measures), or None
        self.last_rows: CollisionRows | None = None
        self.obstacles: list[Obstacle] = []
        self.set_obstacles(obstacles)

    # -- the damper ------------------------------------------------------------------------

    # the damper's settings are fixed: the compiled step copies them when it describes the
    # pairs (other settings: a new CollisionAvoidance, set on the controllers)

    @property
    def safety_distance(self) -> float:
        """``d_s`` (m): every pair is kept at least this far apart."""
        return self._safety_distance

    @property
    def detection_distance(self) -> float:
        """``d_i`` (m): a pair closer than this gets its damper row."""
        return self._detection_distance

    @property
    def approach_speed(self) -> float:
        """``xi`` (m/s): how fast a pair may approach at ``d_i``."""
        return self._approach_speed

    @property
    def response_time(self) -> float:
        """``tau`` (s): how late the robot follows a command (0: as commanded)."""
        return self._response_time

    @property
    def gain(self) -> float:
        """``K`` (1/s): the rate the gap ``g = d - d_s`` may close at, ``d_dot >= -K g``.

        The damper alone closes at ``xi / (d_i - d_s)``. A robot ``tau`` late
        (:attr:`response_time`) goes on by ``tau d_dot`` after the command's gap, so the
        damper holds the gap ahead, ``d_dot >= -(xi / (d_i - d_s)) (g + tau d_dot)``:
        ``1 / K = (d_i - d_s) / xi + tau``, the two time constants in series, never
        faster than the robot follows (docs/design.md 18.3)."""
        return self.approach_speed / (self.detection_distance - self.safety_distance
                                      + self.approach_speed * self.response_time)

    def check(self, model: pin.Model, dt: float) -> None:
        """Refuse (``ValueError``) a controller whose model is not this robot's, or a
        damper unstable at period ``dt`` (``gain dt >= 1``, :attr:`gain` with the response
        time)."""
        if model is not self.model and (model.nq != self.model.nq
                                        or list(model.names) != list(self.model.names)):
            raise ValueError("this collision avoidance was built for another robot model")
        if not self.gain * dt < 1.0:
            raise ValueError(
                f"the collision damper's rate K = xi / (d_i - d_s + xi tau) = {self.gain:g} 1/s "
                f"(tau = response_time {self.response_time:g} s) is unstable at {1.0 / dt:g} Hz "
                f"(needs < {1.0 / dt:g} 1/s): lower approach_speed or widen the detection "
                "distance")

    # -- the obstacles and the pairs -----------------------------------------------------------

    def set_obstacles(self, obstacles: Iterable[Obstacle]) -> None:
        """Replace the obstacles (each an :class:`Obstacle`, at most
        :data:`~constraints.limits.MAX_OBSTACLES`; names made unique)."""
        obstacles = list(obstacles)
        if len(obstacles) > MAX_OBSTACLES:
            raise ValueError(f"obstacles must be at most {MAX_OBSTACLES}, got {len(obstacles)}")
        for obstacle in obstacles:
            if not isinstance(obstacle, Obstacle):
                raise ValueError(f"an obstacle must be a Sphere, Box, Capsule or HalfSpace, "
                                 f"got {obstacle!r}")
        seen: dict[str, int] = {}
        for obstacle in obstacles:
            count = seen[obstacle.name] = seen.get(obstacle.name, 0) + 1
            if count > 1:
                obstacle.name = f"{obstacle.name}{count}"
        self.obstacles = obstacles
        self._build()

    def add_obstacle(self, obstacle: Obstacle) -> None:
        """Add one obstacle."""
        self.set_obstacles([*self.obstacles, obstacle])

    def remove_obstacle(self, obstacle: Obstacle) -> None:
        """Remove one obstacle (``ValueError`` if it is not here)."""
        if not any(item is obstacle for item in self.obstacles):
            raise ValueError(f"{obstacle!r} is not one of the obstacles")
        self.set_obstacles([item for item in self.obstacles if item is not obstacle])

    def set_ports(self, constraints: Iterable[Any]) -> None:
        """Leave the instrument inside each port alone: for every constraint that is a port
        (a hole, :func:`.ports.is_port`), the geometries on its link and the links after it are not
        paired with an obstacle within the detection distance of its position (the body
        the port goes through)."""
        exempt = set()
        robot_count = self._robot_geometry.ngeoms
        for constraint in constraints:
            if not is_port(constraint):
                continue
            joint = self.model.frames[resolve_frame(self.model, constraint.link)].parentJoint
            inside = set(self.model.subtrees[joint])
            port = pin.SE3(np.eye(3), np.asarray(constraint.position, dtype=float))
            point = coal.Sphere(1e-6)
            for k, obstacle in enumerate(self.obstacles):
                if shape_distance(point, port, obstacle.shape(), obstacle.pose()) \
                        > self.detection_distance:
                    continue
                for g, item in enumerate(self._robot_geometry.geometryObjects):
                    if item.parentJoint in inside:
                        exempt.add((g, robot_count + k))
        if exempt != self._exempt:
            self._exempt = exempt
            self._build()

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """Every pair checked, by the names of its links or obstacles."""
        return [(self._names[i], self._names[j]) for i, j in self._pairs]

    def _build(self) -> None:
        """The geometry model of the robot and the obstacles, its pairs and broadphase data."""
        geometry = self._robot_geometry.copy()
        robot_count = geometry.ngeoms
        for obstacle in self.obstacles:
            geometry.addGeometryObject(pin.GeometryObject(
                f"obstacle:{obstacle.name}", 0, 0, obstacle.pose(), obstacle.shape()))
        pairs = list(self._self_pairs)
        for k in range(len(self.obstacles)):
            for g, item in enumerate(self._robot_geometry.geometryObjects):
                if item.parentJoint != 0 and (g, robot_count + k) not in self._exempt:
                    pairs.append((g, robot_count + k))
        for i, j in pairs:
            geometry.addCollisionPair(pin.CollisionPair(i, j))
        self._geometry = geometry
        self._geometry_data = geometry.createData()
        for request in self._geometry_data.distanceRequests:
            request.gjk_tolerance = request.epa_tolerance = GJK_TOLERANCE
        self._pairs = np.array(pairs, dtype=int).reshape(-1, 2)
        #: per pair, its obstacle's index (-1: a pair of two robot geometries)
        self._pair_obstacle = np.where(self._pairs[:, 1] >= robot_count,
                                       self._pairs[:, 1] - robot_count, -1)
        self._pair_indices = np.arange(len(self._pairs))
        #: whether the last step's closest pair was closer than ``d_i - BOUNDING_MARGIN``
        #: (:meth:`_near_pairs`' order: its cost only)
        self._close_last_step = False
        self._boxes: ObstacleBoxes | None = None  # sorted again when obstacles move
        self._names = [*self._links, *(obstacle.name for obstacle in self.obstacles)]
        self._robot_count = robot_count
        robot_objects = self._robot_geometry.geometryObjects
        bounds = [bounding_segment(item.geometry, item.placement) for item in robot_objects]
        #: per robot geometry: its joint, its bounding capsule's ends there (2 n, 3: the
        #: starts then the ends) and radius; per obstacle its bounding capsule's radius
        self._joints = np.array([item.parentJoint for item in robot_objects], dtype=int)
        self._end_joints = np.concatenate([self._joints, self._joints])  # of each end below
        self._joint_list = self._joints.tolist()
        self._local_ends = np.array([start for start, _, _ in bounds]
                                    + [end for _, end, _ in bounds]).reshape(-1, 3)
        self._radii = np.array([radius for _, _, radius in bounds]
                               + [bounding_segment(o.shape(), pin.SE3.Identity())[2]
                                  for o in self.obstacles])
        self._moving_joints = np.unique(self._joints).tolist()
        #: each obstacle's ``center`` array when its bounding segment below was computed
        #: (``move_to`` replaces the array: an obstacle not moved keeps its pose), and the
        #: segments' world ends
        self._placed_centers: list[np.ndarray | None] = [None] * len(self.obstacles)
        self._obstacle_starts = np.zeros((len(self.obstacles), 3))
        self._obstacle_ends = np.zeros((len(self.obstacles), 3))
        self.revision += 1

    def primitives(self) -> CollisionPrimitives:
        """The bodies, obstacles and pairs as primitives, for the compiled step (its
        ``uncovered`` names any shape it cannot measure: a mesh's convex hull)."""
        objects = self._robot_geometry.geometryObjects
        bodies = [primitive(item.geometry) for item in objects]
        obstacles = [obstacle.primitive() for obstacle in self.obstacles]
        return CollisionPrimitives(
            body_names=tuple(item.name for item in objects),
            body_joints=self._joints.copy(),
            body_placements=np.array([item.placement.homogeneous for item in objects]).reshape(-1, 4, 4),
            body_kinds=np.array([kind for kind, _ in bodies], dtype=int),
            body_dimensions=np.array([dimensions for _, dimensions in bodies]).reshape(-1, 3),
            obstacles=tuple(self.obstacles),
            obstacle_kinds=np.array([kind for kind, _, _ in obstacles], dtype=int),
            obstacle_dimensions=np.array([dimensions for _, dimensions, _ in obstacles]).reshape(-1, 3),
            obstacle_rotations=np.array([rotation for _, _, rotation in obstacles]).reshape(-1, 3, 3),
            pairs=self._pairs.copy(),
            pair_names=tuple(f"{first} | {second}" for first, second in self.pairs),
            safety_distance=self.safety_distance, detection_distance=self.detection_distance,
            gain=self.gain)

    # -- the rows ------------------------------------------------------------------------------

    def _update(self, model: pin.Model, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        """Every geometry's world placement (``data.oMi`` must be current); returns the
        world ends ``(starts, ends)`` of the bounding capsules, robot geometries then
        obstacles."""
        geometry, geometry_data = self._geometry, self._geometry_data
        placed = self._placed_centers
        for k, obstacle in enumerate(self.obstacles):
            if obstacle.center is not placed[k]:  # moved (or new): pose it again
                pose = obstacle.pose()
                geometry.geometryObjects[self._robot_count + k].placement = pose
                start, end, _ = bounding_segment(obstacle.shape(), pose)
                self._obstacle_starts[k], self._obstacle_ends[k] = start, end
                placed[k] = obstacle.center
                self._boxes = None
        pin.updateGeometryPlacements(model, data, geometry, geometry_data)
        placements = np.empty((model.njoints, 4, 4))
        for joint in self._moving_joints:
            placements[joint] = data.oMi[joint].homogeneous
        joints = self._end_joints
        ends = (np.einsum("kij,kj->ki", placements[joints, :3, :3], self._local_ends)
                + placements[joints, :3, 3])
        robot_count = self._robot_count
        if not self.obstacles:  # the robot's alone: two stackings fewer (4.5 us a step, measured)
            return ends[:robot_count], ends[robot_count:]
        return (np.vstack([ends[:robot_count], self._obstacle_starts]),
                np.vstack([ends[robot_count:], self._obstacle_ends]))

    def _boxed_pairs(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """The pair indices (ascending) whose bounding capsules' boxes come within the
        detection distance (:mod:`.broadphase`: first the obstacles whose boxes meet the
        robot's, then the pairs whose two boxes come within the distance; a half-space's
        box is the whole space)."""
        robot_count, reach = self._robot_count, self.detection_distance
        if self._boxes is None:
            self._boxes = ObstacleBoxes(starts[robot_count:], ends[robot_count:],
                                        self._radii[robot_count:])
        boxes = self._boxes
        lower, upper = capsule_boxes(starts[:robot_count], ends[:robot_count],
                                     self._radii[:robot_count])
        if boxes.count:
            obstacle = self._pair_obstacle
            kept = obstacle < 0
            near = boxes.near(lower.min(axis=0) - reach, upper.max(axis=0) + reach)
            kept |= near[np.maximum(obstacle, 0)] & ~kept
            lower, upper = np.vstack([lower, boxes.lower]), np.vstack([upper, boxes.upper])
            candidates = np.flatnonzero(kept)
            first, second = self._pairs[candidates, 0], self._pairs[candidates, 1]
        else:  # every pair is the robot's: three index operations fewer (6 us a step, measured)
            candidates, first, second = self._pair_indices, self._pairs[:, 0], self._pairs[:, 1]
        meets = np.all((lower[first] - reach <= upper[second])
                       & (upper[first] + reach >= lower[second]), axis=1)
        return candidates[meets]

    def _capsule_gaps(self, starts: np.ndarray, ends: np.ndarray,
                      pairs: np.ndarray) -> np.ndarray:
        """The gaps (m) between the bounding capsules of the pairs of index ``pairs`` (a
        half-space's pair: the capsule's height above its plane)."""
        first, second = self._pairs[pairs, 0], self._pairs[pairs, 1]
        gaps = (segment_distances(starts[first], ends[first], starts[second], ends[second])
                - self._radii[first] - self._radii[second])
        infinite = ~np.isfinite(gaps)
        if infinite.any():
            for index in np.flatnonzero(infinite).tolist():
                plane = self.obstacles[second[index] - self._robot_count]
                body = first[index]
                heights = [float(plane.normal @ (point - plane.center))
                           for point in (starts[body], ends[body])]
                gaps[index] = min(heights) - self._radii[body]
        return gaps

    def _counted(self, starts: np.ndarray, ends: np.ndarray, pairs: np.ndarray,
                 distances: np.ndarray) -> np.ndarray:
        """A mask over ``pairs`` (measured at ``distances``) of those whose bounding
        capsules come within the detection distance ``d_i``: the pairs the rows and the
        smallest distance are taken over (docs/design.md 18.3).

        A bounding capsule holds its body, so a pair closer than ``d_i - BOUNDING_MARGIN``
        passes without its capsules measured. Only where that leaves the outcome open are
        they measured: the pairs between that and ``d_i`` (a row or none), and, when no
        pair is that close, every pair (the smallest distance may be any of them). With
        a pair that close, a pair at or beyond ``d_i`` is left out unmeasured: it is no
        row and cannot be the smallest."""
        reach = self.detection_distance
        counted = distances < reach - BOUNDING_MARGIN
        open_ = ~counted & (distances < reach) if counted.any() else ~counted
        if open_.any():
            counted[open_] = self._capsule_gaps(starts, ends, pairs[open_]) < reach
        return counted

    def _measured(self, pairs: np.ndarray) -> list[Any]:
        """coal's distance results of the pairs of index ``pairs`` (at the placements of
        the last :meth:`_update`)."""
        return [pin.computeDistance(self._geometry, self._geometry_data, index)
                for index in pairs.tolist()]

    def _near_pairs(self, starts: np.ndarray,
                    ends: np.ndarray) -> tuple[np.ndarray, list[Any]]:
        """The pair indices (ascending) whose bounding capsules come within the detection
        distance, and their coal distance results.

        Two orders give these pairs (docs/design.md 18.3): the capsules' segment distances
        of every pair the boxes let through, then coal on the pairs near (the compiled
        step's order), or coal on every pair the boxes let through, then the capsules only
        where :meth:`_counted` needs them. The segment distances cost about 55 us whatever
        the number of pairs (numpy's cost per call), coal 0.6 us a pair: the second order is
        the cheaper when a pair is closer than ``d_i - BOUNDING_MARGIN`` (it skips the
        segments), the first when none is (it measures only the pairs near). The last
        step's closest pair chooses (:attr:`_close_last_step`); only the cost depends on
        it."""
        boxed = self._boxed_pairs(starts, ends)
        if self._close_last_step:
            results = self._measured(boxed)
            distances = np.array([result.min_distance for result in results])
            kept = np.flatnonzero(self._counted(starts, ends, boxed, distances)).tolist()
            return boxed[kept], [results[k] for k in kept]
        near = boxed[self._capsule_gaps(starts, ends, boxed) < self.detection_distance]
        return near, self._measured(near)

    def rows(self, model: pin.Model, data: pin.Data) -> CollisionRows:
        """The damper rows at the kinematics in ``data`` (``pin.computeJointJacobians`` run
        at the current ``q``): one per pair closer than the detection distance; kept in
        :attr:`last_rows`."""
        self.last_rows = rows = self._rows(model, data)
        self._close_last_step = rows.minimum_distance < self.detection_distance - BOUNDING_MARGIN
        return rows

    def _rows(self, model: pin.Model, data: pin.Data) -> CollisionRows:
        if not len(self._pairs):
            return CollisionRows.empty(model.nv)
        near, results = self._near_pairs(*self._update(model, data))
        if not near.size:
            return CollisionRows.empty(model.nv)
        gain, safety = self.gain, self.safety_distance
        rows, lower, names, distances, witnesses = [], [], [], [], []
        minimum, closest = float("inf"), ""
        jacobians: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}  # per joint
        for index, result in zip(near.tolist(), results):
            distance = float(result.min_distance)
            first, second = self._pairs[index].tolist()
            name = f"{self._names[first]} | {self._names[second]}"
            if distance < minimum:
                minimum, closest = distance, name
            if distance >= self.detection_distance:
                continue
            on_first, on_second = result.getNearestPoint1(), result.getNearestPoint2()
            normal = -np.asarray(result.normal)  # from the second body towards the first
            row = self._point_row(model, data, jacobians, first, on_first, normal)
            bound = -gain * (distance - safety)
            if second < self._robot_count:
                row -= self._point_row(model, data, jacobians, second, on_second, normal)
            else:
                bound += float(normal @ self.obstacles[second - self._robot_count].velocity)
            rows.append(row)
            lower.append(bound)
            names.append(name)
            distances.append(distance)
            witnesses.append((on_first, on_second))
        if not rows:
            return CollisionRows(np.zeros((0, model.nv)), np.zeros(0), (), np.zeros(0),
                                 np.zeros((0, 2, 3)), minimum, closest)
        return CollisionRows(np.array(rows), np.array(lower), tuple(names), np.array(distances),
                             np.array(witnesses), minimum, closest)

    def _point_row(self, model: pin.Model, data: pin.Data,
                   jacobians: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]],
                   geometry_index: int, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
        """``normal^T J_p``: the rate along ``normal`` of the world ``point`` carried by the
        joint of geometry ``geometry_index``, ``J_p = J_v - hat(point - o) J_w``
        (world-aligned), so ``normal^T J_p = normal^T J_v + (arm x normal)^T J_w``; each
        joint's Jacobian taken once a step (``jacobians``)."""
        joint = self._joint_list[geometry_index]
        if joint not in jacobians:
            jacobian = pin.getJointJacobian(model, data, joint, pin.LOCAL_WORLD_ALIGNED)
            jacobians[joint] = (jacobian[:3], jacobian[3:], data.oMi[joint].translation)
        linear, angular, origin = jacobians[joint]
        return normal @ linear + cross(point - origin, normal) @ angular

    def distances(self, model: pin.Model, data: pin.Data) -> list[tuple[str, float]]:
        """Every pair's name and signed distance (m) at the placements in ``data.oMi``
        (no broadphase: for measures and tests)."""
        self._update(model, data)
        result = []
        for index, (first, second) in enumerate(self._pairs.tolist()):
            distance = pin.computeDistance(self._geometry, self._geometry_data, index).min_distance
            result.append((f"{self._names[first]} | {self._names[second]}", float(distance)))
        return result

    def minimum_distance(self, q: np.ndarray) -> tuple[float, str]:
        """The smallest distance (m) over every pair at ``q``, and its pair ("" when none)."""
        data = self.model.createData()
        pin.forwardKinematics(self.model, data, q)
        measured = self.distances(self.model, data)
        if not measured:
            return float("inf"), ""
        name, distance = min(measured, key=lambda item: item[1])
        return distance, name

    # -- description ---------------------------------------------------------------------------

    def to_dict(self) -> dict:
        """The settings and the obstacles, JSON-ready (:meth:`from_dict` rebuilds it); the
        response time only when not 0 (a scene or session of a robot moving as commanded
        reads as before)."""
        settings = {"safety_distance": self.safety_distance,
                    "detection_distance": self.detection_distance,
                    "approach_speed": self.approach_speed, "self_collision": self.self_collision,
                    "disabled_pairs": [list(pair) for pair in self.disabled_pairs],
                    "extra_pairs": [list(pair) for pair in self.extra_pairs],
                    "obstacles": [obstacle.to_dict() for obstacle in self.obstacles]}
        if self.response_time:
            settings["response_time"] = self.response_time
        return settings

    @classmethod
    def from_dict(cls, robot: CollisionRobot, data: Mapping) -> "CollisionAvoidance":
        """Collision avoidance on ``robot`` from :meth:`to_dict` output; bad input raises
        ``ValueError`` naming the field."""
        if not isinstance(data, Mapping):
            raise ValueError(f"collision settings must be an object, got {short_repr(data)}")
        known = {"safety_distance", "detection_distance", "approach_speed", "self_collision",
                 "disabled_pairs", "extra_pairs", "obstacles", "response_time"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"unknown collision field {unknown[0]!r} (its fields: "
                             f"{', '.join(sorted(known))})")
        settings = dict(data)
        obstacles = settings.pop("obstacles", [])
        if not isinstance(obstacles, list):
            raise ValueError(f"obstacles must be a list, got {short_repr(obstacles)}")
        return cls(robot, [Obstacle.from_dict(item) for item in obstacles], **settings)

    def __repr__(self) -> str:
        return (f"CollisionAvoidance({len(self._pairs)} pairs, {len(self.obstacles)} obstacles, "
                f"d_s={self.safety_distance:g} m, d_i={self.detection_distance:g} m, "
                f"xi={self.approach_speed:g} m/s)")
