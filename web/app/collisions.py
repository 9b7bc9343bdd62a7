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
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from constraints.collision import OBSTACLE_TYPES, CollisionAvoidance, CollisionRows, Obstacle
from constraints.limits import MAX_RESPONSE_TIME_S
from constraints.validation import as_number, as_vector, short_repr
from constraints import Constraint
from controllers.base import Controller
from teleop.robots import Robot

from .end_effectors import ee_index
from .limits import MAX_TARGET_DISTANCE
from .placed import PlacedEntry, remove_every

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
        radius, length = (np.asarray(dimensions.get(name, 0.0), dtype=float)
                          for name in ("radius", "length"))
        reach = float(radius) + 0.5 * float(length) * abs(float(obstacle.rotation()[:, 2] @ approach))
    return tip.translation + (FRONT_GAP + reach) * approach


@dataclass
class ObstacleEntry(PlacedEntry):
    """An obstacle placed by the operator (its ``name`` is its id), with where its gizmo
    put it."""

    obstacle: Obstacle = field(kw_only=True)

    @property
    def moved(self) -> Obstacle:
        """What the gizmo moves (:mod:`teleop.loop.moving_geometry`)."""
        return self.obstacle


def check_reach(position: np.ndarray, origin: np.ndarray, what: str) -> None:
    """``ValueError`` when ``position`` is more than :data:`MAX_TARGET_DISTANCE` from
    ``origin`` (world, m)."""
    distance = math.hypot(*(np.asarray(position, dtype=float) - origin))
    if not distance <= MAX_TARGET_DISTANCE:
        raise ValueError(f"{what} position refused: {distance:.3g} m away, more than "
                         f"{MAX_TARGET_DISTANCE:g} m")


@dataclass(frozen=True)
class CollisionSession:
    """What :class:`CollisionScene` reads of the rest of the session (under its lock)."""

    #: every robot's controller (each holds the avoidance while it is on)
    controllers: Callable[[], list[Controller]]
    #: the placed constraints (their ports: the links that go through the wall)
    constraints: Callable[[], list[Constraint]]
    #: the main robot's EE placements now (a new obstacle goes in front of one)
    tips: Callable[[], list[pin.SE3]]
    #: the control period (s): the avoidance's dampers are checked at it
    period: Callable[[], float]


class CollisionScene:
    """The collision avoidance of :class:`web.app.TeleopApp`, a component that owns it:
    the session's :attr:`avoidance`, whether the controllers hold it (:attr:`on`), the
    placed :attr:`obstacles` by id and the rows last measured for each robot
    (:attr:`rows`). Its operator's actions (:meth:`add`, :meth:`move`, :meth:`remove`,
    :meth:`clear`, :meth:`set_on`, :meth:`configure`, :meth:`settings`) take the session's
    lock; the control tick calls :meth:`keep`, :meth:`measure` and
    :meth:`traced_distance` holding it.

    Parameters
    ----------
    robot : the session's robot.
    dt : the control period (s), the avoidance's dampers checked at it.
    on : whether the controllers keep the pairs apart.
    settings : keywords of :data:`SETTINGS` (the others their defaults, self-collision on
        a robot with several arms).
    lock : the session's lock.
    session : what it reads of the rest of the session (:class:`CollisionSession`).
    response_time : ``tau`` (s), how late the session's robot follows a command
        (:attr:`teleop.plants.PlantChoice.response_time`): every avoidance built here
        counts on it (``1 / K = (d_i - d_s) / xi + tau``, docs/design.md 18.3, 18.6),
        whatever the operator's settings or a scene say.
    """

    def __init__(self, robot: Robot, dt: float, on: bool, settings: dict,
                 lock: threading.RLock, session: CollisionSession,
                 response_time: float = 0.0) -> None:
        unknown = sorted(set(settings) - set(SETTINGS))
        if unknown:
            raise ValueError(f"unknown collision setting {unknown[0]!r} ({', '.join(SETTINGS)})")
        if not isinstance(on, (bool, np.bool_)):
            raise ValueError(f"collisions are on (True) or off (False), got {on!r}")
        self.robot = robot
        self._lock = lock
        self._session = session
        #: ``tau`` (s): the response time every avoidance of the session counts on
        self.response_time = as_number(response_time, "response_time", 0.0,
                                       maximum=MAX_RESPONSE_TIME_S)
        settings = {"self_collision": default_self_collision(robot), **settings}
        self.avoidance = CollisionAvoidance(robot, **settings, response_time=self.response_time)
        self.avoidance.check(robot.model, dt)
        self.on = bool(on)
        self.obstacles: dict[str, ObstacleEntry] = {}
        self._ids = itertools.count(1)
        self.rows: dict[str, CollisionRows | None] = {}
        self._data = robot.model.createData()  # the control thread's

    def set_on(self, on: bool) -> None:
        """Whether the controllers keep the pairs apart (the obstacles stay either way)."""
        if not isinstance(on, (bool, np.bool_)):
            raise ValueError(f"collisions are on (True) or off (False), got {on!r}")
        with self._lock:
            self.attach(self._session.controllers(), self.avoidance, bool(on))

    def configure(self, **settings) -> None:
        """Change some of :data:`SETTINGS` (``self_collision``, ``safety_distance`` d_s,
        ``detection_distance`` d_i, ``approach_speed`` xi); the obstacles stay. A bad
        value, or a damper unstable at the control rate, raises ``ValueError`` naming it
        and changes nothing."""
        with self._lock:
            current, dt = self.settings(), self._session.period()
        # built outside the lock (tens of ms with self-collision: the control thread runs on)
        avoidance = self.rebuilt(current, settings, dt)
        with self._lock:
            avoidance.set_obstacles([entry.obstacle for entry in self.obstacles.values()])
            self.attach(self._session.controllers(), avoidance, self.on)

    def attached(self, avoidance: CollisionAvoidance | None = None,
                 on: bool | None = None) -> CollisionAvoidance | None:
        """What the controllers hold: the avoidance when collisions are on, else None."""
        on = self.on if on is None else on
        return (avoidance or self.avoidance) if on else None

    def attach(self, controllers: Iterable[Controller], avoidance: CollisionAvoidance,
               on: bool) -> None:
        """Every one of ``controllers`` holds ``avoidance`` (or none when not ``on``); all
        or nothing: one that refuses it (``ValueError``) leaves every controller as it
        was."""
        attached = avoidance if on else None
        done = []
        try:
            for controller in controllers:
                previous = controller.collisions
                controller.set_collisions(attached)
                done.append((controller, previous))
        except ValueError:
            for controller, previous in done:
                controller.set_collisions(previous)
            raise
        self.avoidance, self.on = avoidance, bool(on)
        self.rows = {}

    def settings(self) -> dict:
        """``on`` and the values of :data:`SETTINGS` now."""
        with self._lock:
            return {"on": self.on,
                    **{name: getattr(self.avoidance, name) for name in SETTINGS}}

    def rebuilt(self, current: dict, settings: dict, dt: float) -> CollisionAvoidance:
        """A new avoidance with ``settings`` over the ``current`` ones (:meth:`settings`),
        this one's pairs and the session's :attr:`response_time`, checked at ``dt``,
        without the obstacles (tens of ms with self-collision: called outside the lock);
        ``ValueError`` naming a bad setting."""
        unknown = sorted(set(settings) - set(SETTINGS))
        if unknown:
            raise ValueError(f"unknown collision setting {unknown[0]!r} ({', '.join(SETTINGS)})")
        old = self.avoidance
        current = {name: value for name, value in current.items() if name in SETTINGS}
        avoidance = CollisionAvoidance(self.robot, **{**current, **settings},
                                       disabled_pairs=old.disabled_pairs,
                                       extra_pairs=old.extra_pairs,
                                       response_time=self.response_time)
        avoidance.check(self.robot.model, dt)
        return avoidance

    def add(self, kind: str, center=None, ee=0, **fields) -> str:
        """Place an obstacle of ``kind`` (:data:`constraints.collision.OBSTACLE_TYPES`)
        with its constructor's ``fields`` (those not given: :func:`obstacle_fields`);
        ``center`` (world, m) or, by default, in front of EE ``ee``'s tip
        (:func:`in_front`). Its id; a bad value raises ``ValueError`` naming the field and
        places nothing."""
        defaults = obstacle_fields(kind)
        unknown = sorted(set(fields) - set(defaults))
        if unknown:
            raise ValueError(f"unknown field {unknown[0]!r} for a {kind} obstacle (its "
                             f"fields: {', '.join(defaults)})")
        ee = ee_index(self.robot, ee)
        with self._lock:
            entry_id = f"{kind}-{next(self._ids)}"
            tip = self._session.tips()[ee]
            try:
                obstacle = OBSTACLE_TYPES[kind](center=tip.translation if center is None
                                                else center, name=entry_id,
                                                **{**defaults, **fields})
            except TypeError as error:
                raise ValueError(f"bad {kind} obstacle: {error}") from None
            if center is None:
                obstacle.move_to(in_front(obstacle, tip))
            check_reach(obstacle.position, tip.translation, "obstacle")
            if entry_id in self.obstacles:
                raise ValueError(f"an obstacle {entry_id!r} is already placed")
            self.avoidance.add_obstacle(obstacle)
            self.obstacles[entry_id] = ObstacleEntry(entry_id, obstacle.position, obstacle=obstacle)
            self.refresh_ports(self._session.constraints())
            return entry_id

    def move(self, entry_id: str, position) -> None:
        """Move an obstacle (its world centre): it glides there, its velocity fed forward."""
        position = as_vector(position, 3, "obstacle position")
        with self._lock:
            entry = self.obstacle(entry_id)
            check_reach(position, entry.obstacle.position, "obstacle")
            entry.goal = position.copy()
            entry.settled = False

    def refresh_ports(self, constraints: list[Constraint]) -> None:
        """The avoidance learns which links go through a port of the placed
        ``constraints`` (after an obstacle or constraint change)."""
        self.avoidance.set_ports(constraints)
        self.rows = {}

    def obstacle(self, entry_id: str) -> ObstacleEntry:
        """The placed obstacle ``entry_id``; ``ValueError`` when there is none."""
        if not isinstance(entry_id, str) or entry_id not in self.obstacles:
            raise ValueError(f"no obstacle {short_repr(entry_id)}")
        return self.obstacles[entry_id]

    def remove(self, entry_id: str) -> None:
        """Remove the obstacle ``entry_id``."""
        with self._lock:
            entry = self.obstacle(entry_id)
            self.avoidance.remove_obstacle(entry.obstacle)
            del self.obstacles[entry_id]
            self.refresh_ports(self._session.constraints())

    def clear(self) -> int:
        """Remove every obstacle; how many there were."""
        with self._lock:
            return remove_every(self.obstacles, self.remove)

    def restore(self, avoidance: CollisionAvoidance, on: bool,
                obstacles: dict[str, ObstacleEntry]) -> None:
        """A scene's avoidance, held when ``on``, with its ``obstacles`` (already in the
        avoidance); the next obstacle ids follow theirs."""
        self.avoidance, self.on, self.rows = avoidance, bool(on), {}
        self.obstacles = obstacles
        numbers = [int(entry_id.rsplit("-", 1)[1]) for entry_id in obstacles
                   if entry_id.rsplit("-", 1)[-1].isdigit()]
        self._ids = itertools.count(max(numbers, default=0) + 1)

    def for_scene(self, collisions: dict | None, obstacles: list[Obstacle],
                  constraints: list[Constraint], dt: float) -> tuple[CollisionAvoidance, bool]:
        """The avoidance a scene asks for (its ``collisions`` settings and ``on``; None, a
        version 1 scene: this one's settings, no obstacle), with its ``obstacles`` and the
        ports of its ``constraints``, counting on the session's :attr:`response_time` (the
        scene's ``response_time``, what the damper counted on where it was saved, is
        checked, not taken: the robot here is this session's), checked at ``dt``, and
        whether the controllers hold it; ``ValueError`` naming the field for settings it
        cannot take. Nothing of this one changes (:meth:`restore` takes it)."""
        if collisions is None:
            settings, on = self.avoidance.to_dict(), self.on
        else:
            settings = {key: value for key, value in collisions.items() if key != "on"}
            on = collisions["on"]
        settings["obstacles"] = []
        try:
            as_number(settings.get("response_time", 0.0), "response_time", 0.0,
                      maximum=MAX_RESPONSE_TIME_S)
            settings["response_time"] = self.response_time
            avoidance = CollisionAvoidance.from_dict(self.robot, settings)
            avoidance.check(self.robot.model, dt)
        except ValueError as error:
            raise ValueError(f"scene collisions: {error}") from None
        avoidance.set_obstacles(obstacles)
        avoidance.set_ports(constraints)
        return avoidance, on

    def keep(self, held: dict[str, CollisionRows]) -> None:
        """The rows each controller computed in its step this tick, kept for the view
        while collisions are on."""
        if self.on:
            self.rows.update(held)

    def measure(self, configurations: dict[str, np.ndarray]) -> None:
        """The avoidance's rows at each given robot's configuration, for the view (the
        control thread): for a robot whose controller computed none in its step
        (:meth:`.tick.Ticker._advance`); none while collisions are off."""
        if not self.on:
            self.rows = {}
            return
        model, data = self.robot.model, self._data
        for which, q in configurations.items():
            pin.computeJointJacobians(model, data, q)
            self.rows[which] = self.avoidance.rows(model, data)

    def traced_distance(self, which: str) -> float:
        """The minimum distance the plots show for robot ``which`` (m): the closest pair
        measured, at most the detection distance (NaN while collisions are off or before a
        measure)."""
        rows = self.rows.get(which)
        if rows is None:
            return math.nan
        return min(rows.minimum_distance, self.avoidance.detection_distance)
