"""``teleop bench``'s problems: their names, their constraints, the configurations and
the twist they are timed at (docs/design.md section 16, the bench).

Beside the built-in robots (one hole on each constrained link), one constraint of each
other type on sda10f (:func:`bench_constraints`), the dual robot's arms close together
without and with collision avoidance, and the generated chains of the scaling runs.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin

from constraints import Barrier, Constraint, Hole, Plane, PointLock
from constraints.collision import CollisionAvoidance
from teleop.robots import BUILTIN_ROBOTS, Robot, load_robot
from teleop.robots.chains import hole_links, load_chain

#: hole distance along the constrained link of each built-in robot (m)
DEFAULT_HOLE_DISTANCE = {"sda10f": 0.08, "ur5_instrument": 0.20, "sda10f_dual": 0.08,
                         "sda10f_dual_mobile": 0.08}
#: A teleoperation-sized body twist of the first EE (a few mm/s, mrad/s): no joint near
#: its velocity limit, so every controller solves the plain constrained problem.
BENCH_TWIST = (0.001, -0.002, 0.0015, 0.005, -0.003, 0.002)
#: the barrier lies this far (m) behind the link point at home, against its normal: the
#: bench's configurations (up to 1 mrad per joint off home) put the point within it in
#: some steps and not in others, so the CJM holds the barrier in some steps only
BARRIER_OFFSET = 2e-4

SCALING_DOFS = (8, 16, 32, 64)
SCALING_HOLES = (1, 2, 4, 8)
#: the problems of one constraint of each other type on sda10f (:func:`bench_constraints`)
CONSTRAINT_PROBLEMS = ("sda10f/plane", "sda10f/lock", "sda10f/barrier")
#: what ``teleop bench`` runs by default: every built-in robot, the constraint problems
#: after sda10f's hole
DEFAULT_PROBLEMS = tuple(name for robot in BUILTIN_ROBOTS for name in
                         (robot, *(p for p in CONSTRAINT_PROBLEMS if p.startswith(f"{robot}/"))))


def scaling_problems(dofs: Sequence[int] = SCALING_DOFS,
                     holes: Sequence[int] = SCALING_HOLES) -> tuple[str, ...]:
    """The scaling runs' problems: one hole on each chain, then holes on the 32-DoF one."""
    return (*(f"chain{dof}" for dof in dofs), *(f"chain32/{count}holes" for count in holes))


def known_problems() -> tuple[str, ...]:
    """Every name the bench takes: the built-in robots, the constraint problems and the
    scaling runs' chains."""
    return (*BUILTIN_ROBOTS, *CONSTRAINT_PROBLEMS, *scaling_problems())


def problem_labels(name: str) -> tuple[str, ...]:
    """The timed problems of a name: the dual robot's arms close together too, without
    and with collision avoidance (``sda10f_dual/close``, ``sda10f_dual/collisions``: every
    self-collision pair, a few within the detection distance, :func:`close_arms`)."""
    return (name, f"{name}/close", f"{name}/collisions") if name == "sda10f_dual" else (name,)


def bench_configurations(robot: Robot, holes: Sequence[Constraint], iterations: int,
                         seed: int = 0, base: np.ndarray | None = None) -> np.ndarray:
    """``iterations`` configurations near ``base`` (default: home): offsets of at most
    1e-3 rad or m per velocity coordinate with their components across the equality
    constraints' rows removed (on the constraints to first order: a drift of micrometres
    to correct), on the configuration manifold (nq != nv on a base)."""
    base = robot.q_home if base is None else base
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-1e-3, 1e-3, (iterations, robot.model.nv))
    rows = _hole_rows(robot, [hole for hole in holes if hole.is_equality], base)
    if len(rows):  # on the equalities to first order: 62 joints of chain64 off by 1e-3
        offsets -= offsets @ rows.T @ np.linalg.pinv(rows).T  # would put its hole 12 mm off
    return np.array([pin.integrate(robot.model, base, offset) for offset in offsets])


@dataclass(frozen=True)
class Problem:
    """One timed problem: its robot and constraints, the configuration they are placed at
    (the configurations are drawn near it) and the collision avoidance (or None)."""

    label: str
    robot: Robot
    constraints: tuple[Constraint, ...]
    base: np.ndarray
    collisions: CollisionAvoidance | None = None


def bench_problem_named(label: str) -> Problem:
    """The problem of a :func:`known_problems` name or of a :func:`problem_labels` label,
    built the same way in every process (the allocation count rebuilds it)."""
    name, _, variant = label.partition("/")
    if name.startswith("chain"):
        dof = int(name.removeprefix("chain"))
        robot = _loaded(name)
        count = int(variant.removesuffix("holes")) if variant else 1
        constraints = [Hole.on_link(robot, robot.q_home, 0.05, link=link)
                       for link in hole_links(dof, count)]
        return Problem(label, robot, tuple(constraints), robot.q_home)
    robot = _loaded(name)
    if variant in ("close", "collisions"):
        base = _close_arms(name)
        collisions = CollisionAvoidance(robot) if variant == "collisions" else None
        return Problem(label, robot, tuple(bench_holes(robot, base)), base, collisions)
    return Problem(label, robot, tuple(bench_constraints(robot, variant or "hole")),
                   robot.q_home)


@functools.cache
def _loaded(name: str) -> Robot:
    """A built-in robot or a generated chain (``chainN``), loaded once a process."""
    return load_chain(int(name.removeprefix("chain"))) if name.startswith("chain") \
        else load_robot(name)


@functools.cache
def _close_arms(name: str) -> np.ndarray:
    """:func:`close_arms` of a built-in robot, found once a process."""
    robot = _loaded(name)
    return close_arms(robot, CollisionAvoidance(robot))


def close_arms(robot: Robot, collisions: CollisionAvoidance, seed: int = 1,
               tries: int = 2000) -> np.ndarray:
    """A configuration near home (normal offsets of 0.4 rad, ``seed``) where the most pairs
    between the two arms lie within the detection distance, none closer than 1 cm: the
    first found with four such pairs, else the best of ``tries``."""
    model = robot.model
    data = model.createData()
    rng = np.random.default_rng(seed)
    best, best_count = robot.q_home.copy(), -1
    for _ in range(tries):
        q = pin.integrate(model, robot.q_home, rng.normal(scale=0.4, size=model.nv))
        pin.computeJointJacobians(model, data, q)
        rows = collisions.rows(model, data)
        if rows.size == 0 or rows.minimum_distance < 0.01:
            continue
        count = sum("left" in pair and "right" in pair for pair in rows.pairs)
        if count > best_count:
            best, best_count = q, count
        if count >= 4:
            break
    return best


def bench_twist(robot: Robot, holes: Sequence[Constraint],
                base: np.ndarray | None = None) -> np.ndarray:
    """The stacked twist the bench asks for: :data:`BENCH_TWIST` for the first EE, and for
    the others what the least-norm ``qd`` with ``A qd = 0`` (the holes at home) and
    ``J_e1 qd = BENCH_TWIST`` gives them, so that the twists are consistent with the holes
    (two trocars on one torso cannot meet any pair, docs/design.md section 11.2), at
    ``base`` (default: home)."""
    model, data = _kinematics_at(robot, base)
    first, *others = robot.ee_frame_ids
    rows = np.vstack([_hole_rows(robot, holes, base),
                      pin.getFrameJacobian(model, data, first, pin.LOCAL)])
    goal = np.concatenate([np.zeros(sum(hole.dim for hole in holes)), BENCH_TWIST])
    qd = np.linalg.lstsq(rows, goal, rcond=None)[0]
    return np.concatenate([BENCH_TWIST, *(pin.getFrameJacobian(model, data, frame, pin.LOCAL) @ qd
                                          for frame in others)])


def _kinematics_at(robot: Robot, base: np.ndarray | None) -> tuple[pin.Model, pin.Data]:
    """The model and a data with its joint Jacobians and frame placements at ``base``
    (default: home)."""
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, robot.q_home if base is None else base)
    pin.updateFramePlacements(model, data)
    return model, data


def _hole_rows(robot: Robot, holes: Sequence[Constraint],
               base: np.ndarray | None = None) -> np.ndarray:
    """The constraints' stacked rows ``A`` (``A qd = b``; a barrier's as an equality) at
    ``base`` (default: home)."""
    model, data = _kinematics_at(robot, base)
    return np.vstack([hole.rows(model, data, model.getFrameId(hole.link))[0] for hole in holes]
                     or [np.zeros((0, model.nv))])


def bench_holes(robot: Robot, base: np.ndarray | None = None) -> list[Constraint]:
    """One hole on each of ``robot.constrained_links``, at the robot's
    :data:`DEFAULT_HOLE_DISTANCE` (0.1 m for a robot not listed) along it, at ``base``
    (default: home)."""
    distance = DEFAULT_HOLE_DISTANCE.get(robot.name, 0.1)
    base = robot.q_home if base is None else base
    return [Hole.on_link(robot, base, distance=distance, link=link)
            for link in robot.constrained_links]


def bench_constraints(robot: Robot, kind: str) -> list[Constraint]:
    """One constraint of ``kind`` (``hole``, ``plane``, ``lock``, ``barrier``) at home on
    the first constrained link's point where the hole would be (:func:`bench_holes`):

    * a plane through the point whose normal is the point's motion across the link axis
      (the least-norm ``qd`` giving :data:`BENCH_TWIST`): the plane stops that motion;
    * a point lock on the point (3 rows: with the 6-row twist on 8 joints, least squares);
    * a barrier with that normal turned against the motion (the point moves towards it),
      :data:`BARRIER_OFFSET` behind the point: held in the steps that put the point
      within about ``|n . v| / K`` of it, free in the others (the table says how many)."""
    if kind == "hole":
        return bench_holes(robot)
    link = robot.constrained_links[0]
    distance = DEFAULT_HOLE_DISTANCE.get(robot.name, 0.1)
    if kind == "lock":
        return [PointLock.on_link(robot, robot.q_home, distance=distance, link=link)]
    normal = motion_across_link(robot, link)
    if kind == "plane":
        return [Plane.through_link_point(robot, robot.q_home, normal, distance=distance,
                                         link=link)]
    if kind == "barrier":
        return [Barrier.through_link_point(robot, robot.q_home, -normal, distance=distance,
                                           link=link, offset=BARRIER_OFFSET)]
    raise ValueError(f"unknown constraint problem {kind!r}: hole, plane, lock or barrier")


def motion_across_link(robot: Robot, link: str) -> np.ndarray:
    """The unit world direction of the velocity across ``link``'s axis of its point
    :data:`DEFAULT_HOLE_DISTANCE` along it, at home, under the least-norm ``qd`` with
    ``J_e1 qd =`` :data:`BENCH_TWIST`."""
    model = robot.model
    data = model.createData()
    pin.computeJointJacobians(model, data, robot.q_home)
    pin.updateFramePlacements(model, data)
    qd = np.linalg.lstsq(pin.getFrameJacobian(model, data, robot.ee_frame_ids[0], pin.LOCAL),
                         np.array(BENCH_TWIST), rcond=None)[0]
    frame = model.getFrameId(link)
    rotation = data.oMf[frame].rotation
    axis = np.asarray(robot.link_axes[link])
    point = DEFAULT_HOLE_DISTANCE.get(robot.name, 0.1) * axis
    twist = pin.getFrameJacobian(model, data, frame, pin.LOCAL) @ qd
    velocity = rotation @ (twist[:3] + np.cross(twist[3:], point))
    axis_world = rotation @ axis
    across = velocity - (velocity @ axis_world) * axis_world
    return across / np.linalg.norm(across)
