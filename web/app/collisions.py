"""Collision avoidance in the browser session (docs/design.md section 18): one
:class:`constraints.collision.CollisionAvoidance` for the session's robot, attached to the
main and the ghost controllers; the obstacles the operator adds, moves and removes; the
rows the view shows (the highlighted pairs, the minimum distance): those each controller
computed for its last step.

Obstacles are placed from their kind's constructor (:data:`OBSTACLE_TYPES`): the fields the
operator does not give take the kind's own default, else :data:`FIELD_DEFAULTS`; the
centre goes :data:`FRONT_GAP` in front of a tip (along its tool's z axis, the surface that
far from the tip; a half-space's boundary that far from the tip). An obstacle moves like a
constraint's geometry: it glides to where the operator put it, its velocity fed forward
(:mod:`teleop.loop.moving_geometry`).
"""

from __future__ import annotations

import inspect
import itertools
import math
import threading
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from constraints.collision import OBSTACLE_TYPES, CollisionAvoidance, CollisionRows, Obstacle
from constraints.validation import as_vector, short_repr
from teleop.loop import LoopConfig, TeleopLoop
from teleop.robots import Robot

from .limits import MAX_TARGET_DISTANCE

#: a new obstacle's surface is this far (m) in front of the tip it is placed at
FRONT_GAP = 0.1
#: values of the constructor fields without a default of their own (m, m/s)
FIELD_DEFAULTS = {"radius": 0.04, "length": 0.1, "size": (0.08, 0.08, 0.08),
                  "normal": (0.0, 0.0, 1.0)}
#: the fields an operator never gives: set by the placement and the motion
PLACED_FIELDS = ("center", "velocity", "name")
#: the collision settings an operator may change, by constructor keyword
SETTINGS = ("self_collision", "safety_distance", "detection_distance", "approach_speed")


def default_self_collision(robot: Robot) -> bool:
    """Self-collision is checked by default on a robot with several arms (end effectors),
    where one arm can be driven into the other."""
    return len(robot.ee_frames) > 1


def obstacle_fields(kind: str) -> dict[str, object]:
    """The fields an operator gives for an obstacle of ``kind`` and their defaults (the
    constructor's, else :data:`FIELD_DEFAULTS`), in the constructor's order."""
    if kind not in OBSTACLE_TYPES:
        raise ValueError(f"unknown obstacle kind {kind!r}: {', '.join(OBSTACLE_TYPES)}")
    fields = {}
    for name, parameter in inspect.signature(OBSTACLE_TYPES[kind]).parameters.items():
        if name in PLACED_FIELDS:
            continue
        default = parameter.default
        if default is inspect.Parameter.empty:
            default = FIELD_DEFAULTS.get(name)
        if default is None:
            raise ValueError(f"no default for the {kind} obstacle's field {name!r}")
        fields[name] = default
    return fields


def in_front(obstacle: Obstacle, tip: pin.SE3) -> np.ndarray:
    """Where ``obstacle``'s centre goes so that its surface is :data:`FRONT_GAP` in front
    of ``tip`` along the tool's z axis; an unbounded shape (a half-space, no dimensions)
    has its boundary :data:`FRONT_GAP` from the tip on the far side of its normal."""
    approach = tip.rotation[:, 2]
    reach = 0.0
    dimensions = obstacle.dimensions()
    if not dimensions:
        return tip.translation - FRONT_GAP * obstacle.rotation()[:, 2]
    if "edges" in dimensions:
        reach = 0.5 * float(np.abs(obstacle.rotation().T @ approach) @ np.asarray(dimensions["edges"]))
    elif "radius" in dimensions:
        reach = float(dimensions["radius"]) + 0.5 * float(dimensions.get("length", 0.0)) * abs(
            float(obstacle.rotation()[:, 2] @ approach))
    return tip.translation + (FRONT_GAP + reach) * approach


@dataclass
class ObstacleEntry:
    """An obstacle placed by the operator (its ``name`` is its id), with where its gizmo
    put it."""

    id: str
    obstacle: Obstacle
    goal: np.ndarray  # where the operator put it (the control loop moves it there)
    settled: bool = True  # at its goal and at rest: the tick leaves it alone

    @property
    def kind(self) -> str:
        return self.obstacle.kind

    @property
    def moved(self) -> Obstacle:
        """What the gizmo moves (:mod:`teleop.loop.moving_geometry`)."""
        return self.obstacle


class Collisions:
    """The collision avoidance of :class:`web.app.TeleopApp` (its state: ``avoidance``,
    whether the controllers hold it, ``collisions_on``, the placed ``obstacles`` by id,
    and the rows last measured for each robot, ``collision_rows``)."""

    robot: Robot
    config: LoopConfig
    loops: dict[str, TeleopLoop]
    entries: dict
    avoidance: CollisionAvoidance
    collisions_on: bool
    obstacles: dict[str, ObstacleEntry]
    collision_rows: dict[str, CollisionRows | None]
    _obstacle_ids: itertools.count
    _collision_data: pin.Data
    _lock: threading.RLock
    _view_data: pin.Data

    def _init_collisions(self, on: bool, settings: dict) -> None:
        """The session's avoidance: ``settings`` (keywords of :data:`SETTINGS`; the others
        their defaults, self-collision on a robot with several arms), held by the
        controllers when ``on``."""
        unknown = sorted(set(settings) - set(SETTINGS))
        if unknown:
            raise ValueError(f"unknown collision setting {unknown[0]!r} ({', '.join(SETTINGS)})")
        if not isinstance(on, (bool, np.bool_)):
            raise ValueError(f"collisions are on (True) or off (False), got {on!r}")
        settings = {"self_collision": default_self_collision(self.robot), **settings}
        self.avoidance = CollisionAvoidance(self.robot, **settings)
        self.avoidance.check(self.robot.model, self.config.dt)
        self.collisions_on = bool(on)
        self.obstacles = {}
        self._obstacle_ids = itertools.count(1)
        self.collision_rows = {}
        self._collision_data = self.robot.model.createData()  # the control thread's

    def _attached(self, avoidance: CollisionAvoidance | None = None,
                  on: bool | None = None) -> CollisionAvoidance | None:
        """What the controllers hold: the avoidance when collisions are on, else None."""
        on = self.collisions_on if on is None else on
        return (avoidance or self.avoidance) if on else None

    def _attach(self, avoidance: CollisionAvoidance, on: bool) -> None:
        """Every controller holds ``avoidance`` (or none when not ``on``); all or nothing:
        one that refuses it (``ValueError``) leaves every controller as it was."""
        attached = avoidance if on else None
        done = []
        try:
            for loop in self.loops.values():
                previous = loop.controller.collisions
                loop.controller.set_collisions(attached)
                done.append((loop.controller, previous))
        except ValueError:
            for controller, previous in done:
                controller.set_collisions(previous)
            raise
        self.avoidance, self.collisions_on = avoidance, bool(on)
        self.collision_rows = {}

    def set_collisions_on(self, on: bool) -> None:
        """Whether the controllers keep the pairs apart (the obstacles stay either way)."""
        if not isinstance(on, (bool, np.bool_)):
            raise ValueError(f"collisions are on (True) or off (False), got {on!r}")
        with self._lock:
            self._attach(self.avoidance, bool(on))

    def set_collision_settings(self, **settings) -> None:
        """Change some of :data:`SETTINGS` (``self_collision``, ``safety_distance`` d_s,
        ``detection_distance`` d_i, ``approach_speed`` xi); the obstacles stay. A bad
        value, or a damper unstable at the control rate, raises ``ValueError`` naming it
        and changes nothing."""
        unknown = sorted(set(settings) - set(SETTINGS))
        if unknown:
            raise ValueError(f"unknown collision setting {unknown[0]!r} ({', '.join(SETTINGS)})")
        with self._lock:
            old = self.avoidance
            current = {name: getattr(old, name) for name in SETTINGS}
        # built outside the lock (tens of ms with self-collision: the control thread runs on)
        avoidance = CollisionAvoidance(self.robot, **{**current, **settings},
                                       disabled_pairs=old.disabled_pairs,
                                       extra_pairs=old.extra_pairs)
        avoidance.check(self.robot.model, self.config.dt)
        with self._lock:
            avoidance.set_obstacles([entry.obstacle for entry in self.obstacles.values()])
            self._attach(avoidance, self.collisions_on)

    def collision_settings(self) -> dict:
        """``on`` and the values of :data:`SETTINGS` now."""
        with self._lock:
            return {"on": self.collisions_on,
                    **{name: getattr(self.avoidance, name) for name in SETTINGS}}

    # -- obstacles ---------------------------------------------------------------------------

    def add_obstacle(self, kind: str, center=None, ee=0, **fields) -> str:
        """Place an obstacle of ``kind`` (:data:`OBSTACLE_TYPES`) with its constructor's
        ``fields`` (those not given: :func:`obstacle_fields`); ``center`` (world, m) or,
        by default, in front of EE ``ee``'s tip (:func:`in_front`). Its id; a bad value
        raises ``ValueError`` naming the field and places nothing."""
        defaults = obstacle_fields(kind)
        unknown = sorted(set(fields) - set(defaults))
        if unknown:
            raise ValueError(f"unknown field {unknown[0]!r} for a {kind} obstacle (its "
                             f"fields: {', '.join(defaults)})")
        ee = self.ee_index(ee)
        with self._lock:
            entry_id = f"{kind}-{next(self._obstacle_ids)}"
            tip = self.loops["main"].ee_placements()[ee]
            values = {**defaults, **fields}
            try:
                obstacle = OBSTACLE_TYPES[kind](center=tip.translation if center is None
                                                else center, name=entry_id, **values)
            except TypeError as error:
                raise ValueError(f"bad {kind} obstacle: {error}") from None
            if center is None:
                obstacle.move_to(in_front(obstacle, tip))
            self._check_reach(obstacle.position, tip.translation, "obstacle")
            self._place_obstacle(ObstacleEntry(entry_id, obstacle, obstacle.position))
            return entry_id

    def _check_reach(self, position: np.ndarray, origin: np.ndarray, what: str) -> None:
        distance = math.hypot(*(np.asarray(position, dtype=float) - origin))
        if not distance <= MAX_TARGET_DISTANCE:
            raise ValueError(f"{what} position refused: {distance:.3g} m away, more than "
                             f"{MAX_TARGET_DISTANCE:g} m")

    def _place_obstacle(self, entry: ObstacleEntry) -> None:
        """Add ``entry`` to the avoidance (caller holds the lock)."""
        if entry.id in self.obstacles:
            raise ValueError(f"an obstacle {entry.id!r} is already placed")
        self.avoidance.add_obstacle(entry.obstacle)
        self.obstacles[entry.id] = entry
        self._refresh_ports()

    def _refresh_ports(self) -> None:
        """The avoidance learns which links go through a port (after an obstacle change)."""
        self.avoidance.set_ports([entry.constraint for entry in self.entries.values()])
        self.collision_rows = {}

    def move_obstacle(self, entry_id: str, position) -> None:
        """Move an obstacle (its world centre): it glides there, its velocity fed forward."""
        position = as_vector(position, 3, "obstacle position")
        with self._lock:
            entry = self._obstacle(entry_id)
            self._check_reach(position, entry.obstacle.position, "obstacle")
            entry.goal = position.copy()
            entry.settled = False

    def remove_obstacle(self, entry_id: str) -> None:
        with self._lock:
            entry = self._obstacle(entry_id)
            self.avoidance.remove_obstacle(entry.obstacle)
            del self.obstacles[entry_id]
            self._refresh_ports()

    def clear_obstacles(self) -> int:
        """Remove every obstacle; how many there were."""
        with self._lock:
            ids = list(self.obstacles)
            for entry_id in ids:
                self.remove_obstacle(entry_id)
            return len(ids)

    def _obstacle(self, entry_id: str) -> ObstacleEntry:
        if not isinstance(entry_id, str) or entry_id not in self.obstacles:
            raise ValueError(f"no obstacle {short_repr(entry_id)}")
        return self.obstacles[entry_id]

    # -- the rows the view shows ---------------------------------------------------------------

    def _measure_collisions(self, configurations: dict[str, np.ndarray]) -> None:
        """The avoidance's rows at each given robot's configuration, for the view (the
        control thread, caller holds the lock): for a robot whose controller computed none
        in its step (:meth:`Tick._advance`); none while collisions are off."""
        if not self.collisions_on:
            self.collision_rows = {}
            return
        model, data = self.robot.model, self._collision_data
        for which, q in configurations.items():
            pin.computeJointJacobians(model, data, q)
            self.collision_rows[which] = self.avoidance.rows(model, data)

    def traced_distance(self, which: str) -> float:
        """The minimum distance the plots show for robot ``which`` (m): the closest pair
        measured, at most the detection distance (NaN while collisions are off or before a
        measure)."""
        rows = self.collision_rows.get(which)
        if rows is None:
            return math.nan
        return min(rows.minimum_distance, self.avoidance.detection_distance)
