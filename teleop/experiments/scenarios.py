"""Named, deterministic operator trajectories for comparing controllers.

A scenario builds a :class:`Plan`: the robot, the start configuration, fresh constraint
objects (each controller run gets its own, since a moving hole is mutated), the operator
target ``T*(t)`` (one per EE of a several-EE robot) and, for moving geometry, what moves
at time ``t``. Every trajectory starts at the EE's home pose with zero velocity (smooth
ramps), so no controller is handed a step.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from constraints import Barrier, Constraint, Hole, Plane
from constraints.collision import Box, Capsule, CollisionAvoidance, Sphere
from teleop.robots import Robot, load_robot

from .placement import placement
from .plan import Plan, home_pose, home_poses, link_placement, smoothstep


def operator_motion(start: pin.SE3, amplitude: Sequence[float], frequencies: Sequence[float],
                    angle_amplitude: float, ramp: float = 2.5,
                    scale: float = 1.0) -> Callable[[float], pin.SE3]:
    """Smooth, operator-like 3D motion: incommensurate sinusoids in position and attitude.

    Position offsets (world frame) ``A_i sin(2 pi f_i t)``; attitude wobble of
    ``angle_amplitude`` rad about a slowly turning axis; both faded in over ``ramp`` s;
    the position amplitudes multiplied by ``scale`` (a robot's reach, :mod:`.placement`).
    """
    amplitudes = scale * np.asarray(amplitude, dtype=float)
    frequencies_hz = np.asarray(frequencies, dtype=float)

    def target(t: float) -> pin.SE3:
        envelope = smoothstep(t / ramp)
        offset = envelope * amplitudes * np.sin(2.0 * np.pi * frequencies_hz * t)
        wobble = envelope * angle_amplitude * np.array([
            math.sin(2 * math.pi * 0.13 * t), math.sin(2 * math.pi * 0.21 * t + 1.0),
            math.sin(2 * math.pi * 0.09 * t + 2.0)])
        return pin.SE3(start.rotation @ pin.exp3(wobble), start.translation + offset)

    return target


# ----------------------------------------------------------------------------- scenarios

#: Operator motion on the sda10f: +-1.5 cm, 0.1-0.2 Hz, +-0.03 rad. With the hole 8 cm
#: along link 6 the arm needs about 40 rad/s of joint speed per m/s at the EE (measured at
#: home), so this slow, small motion already asks for up to 0.7 rad/s.
PAPER_MOTION = ((0.015, 0.011, 0.011), (0.14, 0.19, 0.10), 0.03)


def _paper_hole(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    where = placement(robot, "sda10f", 0.08)
    return Plan(
        "paper-hole", robot, q0, 10.0,
        lambda: [Hole.on_link(robot, q0, distance=where.hole_distance)],
        operator_motion(start, *PAPER_MOTION, scale=where.scale),
        description="sda10f, hole on link 6 (6 joints before, 2 after), operator-like 3D motion"
        if robot.name == "sda10f" else _elsewhere(robot, where, "operator-like 3D motion"))


def _paper_plane(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    link = link_placement(robot, q0, robot.constrained_link)
    normal = link.rotation[:, 1]  # the paper's plane: no velocity along y of F_c (eq 7)
    return Plan(
        "paper-plane", robot, q0, 10.0,
        lambda: [Plane.through_link_point(robot, q0, normal=normal, distance=0.08)],
        operator_motion(start, *PAPER_MOTION),
        description="sda10f, the paper's plane on link 6 (no motion along the normal)")


def _trocar_circle(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    where = placement(robot, "ur5_instrument", 0.2)
    radius, period = 0.03 * where.scale, 4.0

    def target(t: float) -> pin.SE3:
        r = radius * smoothstep(t / 1.5)  # spiral out from the home tip position
        phase = 2.0 * math.pi * t / period
        offset = np.array([r * math.cos(phase), r * math.sin(phase), 0.0])
        return pin.SE3(start.rotation, start.translation + offset)

    return Plan(
        "trocar-circle", robot, q0, 10.0,
        lambda: [Hole.on_link(robot, q0, distance=where.hole_distance)],
        target,
        description="ur5_instrument, trocar on the shaft, the tip traces a 3 cm circle"
        if robot.name == "ur5_instrument"
        else _elsewhere(robot, where, f"the tip traces a circle of {radius * 100:.3g} cm"))


def _insertion(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    shaft = link_placement(robot, q0, robot.constrained_link).rotation @ robot.link_axis

    def target(t: float) -> pin.SE3:
        depth = 0.05 * 0.5 * (1.0 - math.cos(2.0 * math.pi * 0.2 * t))  # 0 -> 5 cm -> 0
        return pin.SE3(start.rotation, start.translation + depth * shaft)

    return Plan(
        "insertion", robot, q0, 10.0,
        lambda: [Hole.on_link(robot, q0, distance=0.2)],
        target,
        description="ur5_instrument, the tip moves 5 cm along the shaft: the contact point slides")


def _moving_trocar(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    centre = Hole.on_link(robot, q0, distance=0.2).center
    direction = np.array([1.0, 0.0, 1.0]) / math.sqrt(2.0)
    amplitude, frequency = 0.005, 0.25

    def update(t: float, constraints: list[Constraint], q: np.ndarray) -> None:
        omega = 2.0 * math.pi * frequency
        constraints[0].move_to(centre + amplitude * math.sin(omega * t) * direction,
                               velocity=amplitude * omega * math.cos(omega * t) * direction)

    return Plan(
        "moving-trocar", robot, q0, 10.0,
        lambda: [Hole.on_link(robot, q0, distance=0.2)],
        operator_motion(start, (0.01, 0.01, 0.0), (0.19, 0.27, 0.0), 0.0),
        update,
        description="ur5_instrument, the trocar breathes +-5 mm at 0.25 Hz, the robot follows")


def _near_singular(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    q_singular = q0.copy()
    q_singular[6] = 0.02  # joint B near 0: joint T lines up with the link axis
    goal = home_pose(robot, q_singular)
    motion = pin.log6(start.actInv(goal)).vector

    def target(t: float) -> pin.SE3:
        return start * pin.exp6(smoothstep(t / 5.0) * motion)

    return Plan(
        "near-singular", robot, q0, 10.0,
        lambda: [Hole.on_link(robot, q0, distance=0.08)],
        target,
        description="sda10f, the target asks for joint B near 0 where Jbar is singular")


def _joint_limits(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    where = placement(robot, "ur5_instrument", 0.2)

    def target(t: float) -> pin.SE3:
        angle = 1.7 * smoothstep(t / 5.0)  # the wrist pitch limit is 1.4 rad
        return pin.SE3(start.rotation @ pin.exp3(np.array([angle, 0.0, 0.0])), start.translation)

    return Plan(
        "joint-limits", robot, q0, 10.0,
        lambda: [Hole.on_link(robot, q0, distance=where.hole_distance)],
        target,
        description="ur5_instrument, the target pitches the tip 1.7 rad: the wrist limit is 1.4"
        if robot.name == "ur5_instrument"
        else _elsewhere(robot, where, "the target pitches the tip 1.7 rad"))


def _barrier(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    floor = start.translation - np.array([0.0, 0.0, 0.015])

    def make() -> list[Constraint]:
        return [Hole.on_link(robot, q0, distance=0.2),
                Barrier(robot.ee_frame, np.zeros(3), floor, [0.0, 0.0, 1.0])]

    def target(t: float) -> pin.SE3:
        down = 0.03 * smoothstep(t / 3.0)
        sideways = 0.02 * smoothstep((t - 3.0) / 4.0)
        return pin.SE3(start.rotation, start.translation + np.array([sideways, 0.0, -down]))

    return Plan(
        "barrier", robot, q0, 10.0, make, target,
        description="ur5_instrument, the tip is pushed 3 cm down onto a floor 1.5 cm below it")


def _multi(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)

    def make() -> list[Constraint]:
        return [Hole.on_link(robot, q0, distance=0.08),
                Plane.through_link_point(robot, q0, normal=[0.0, 0.6, 0.8],
                                         link_point=[0.0, 0.1, -0.02], link="arm_link_3_e")]

    return Plan(
        "multi", robot, q0, 10.0, make,
        operator_motion(start, *PAPER_MOTION),
        description="sda10f, a hole on link 6 and a plane on link 3 at once (5 DoF left)")


def lissajous(start: np.ndarray, amplitude: Sequence[float], frequencies: Sequence[float],
              phases: Sequence[float], ramp: float = 2.5) -> Callable[[float], np.ndarray]:
    """A smooth closed path about ``start`` (world, m): ``A_i sin(2 pi f_i t + phi_i)`` per
    axis, faded in over ``ramp`` s (zero velocity at ``t = 0``, when it is at ``start``)."""
    amplitudes, frequencies_hz, phases_rad = (np.asarray(x, dtype=float)
                                              for x in (amplitude, frequencies, phases))

    def point(t: float) -> np.ndarray:
        return start + smoothstep(t / ramp) * amplitudes * (
            np.sin(2.0 * np.pi * frequencies_hz * t + phases_rad) - np.sin(phases_rad))

    return point


#: Gains of the reference run of :func:`tips_through_constraints` (1/s): tip tracking, and
#: the pull towards the start posture in the null space of the constraints and tips.
REFERENCE_GAIN, REFERENCE_POSTURE_GAIN = 20.0, 5.0


def tips_through_constraints(robot: Robot, q0: np.ndarray, constraints: Sequence[Constraint],
                             tips: Sequence[Callable[[float], np.ndarray]], duration: float,
                             dt: float = 1e-3) -> Callable[[float], list[pin.SE3]]:
    """EE targets the robot can meet exactly: the EE poses of a kinematic reference run in
    which each EE's tip follows its path ``tips[i](t)`` and the constraints hold, each EE's
    orientation being what its constraints leave it (docs/design.md section 11.2).

    The run integrates (``pin.integrate``, every ``dt``) the least-norm solution of
    ``[A; J_p] qd = [b; p*' + K (p* - p)]`` (the equality rows ``A qd = b`` of every
    constraint, each EE's world-aligned linear Jacobian ``J_p``) plus ``-K_q (q - q0)``
    projected on its null space. It runs once, at the first call; targets between its
    samples are interpolated on SE(3).
    """
    model = robot.model
    samples: list[list[pin.SE3]] = []

    def run() -> None:
        data = model.createData()
        frames = [model.getFrameId(c.link) for c in constraints]
        q = np.array(q0, dtype=float)
        for k in range(int(math.ceil(duration / dt)) + 2):
            t = k * dt
            pin.computeJointJacobians(model, data, q)
            pin.updateFramePlacements(model, data)
            samples.append([data.oMf[frame].copy() for frame in robot.ee_frame_ids])
            rows, rhs = [], []
            for constraint, frame in zip(constraints, frames):
                A, b = constraint.rows(model, data, frame)
                rows.append(A)
                rhs.append(b)
            for tip, frame in zip(tips, robot.ee_frame_ids):
                rows.append(pin.getFrameJacobian(model, data, frame, pin.LOCAL_WORLD_ALIGNED)[:3])
                rhs.append((tip(t + dt) - tip(t)) / dt
                           + REFERENCE_GAIN * (tip(t) - data.oMf[frame].translation))
            stacked = np.vstack(rows)
            inverse = np.linalg.pinv(stacked)
            posture = -REFERENCE_POSTURE_GAIN * pin.difference(model, q0, q)
            qd = inverse @ np.concatenate(rhs) + posture - inverse @ (stacked @ posture)
            q = pin.integrate(model, q, qd * dt)

    def target(t: float) -> list[pin.SE3]:
        if not samples:
            run()
        k = min(int(t / dt), len(samples) - 2)
        fraction = min(max(t / dt - k, 0.0), 1.0)
        return [before * pin.exp6(fraction * pin.log6(before.actInv(after)).vector)
                for before, after in zip(samples[k], samples[k + 1])]

    return target


def _bimanual_trocars(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()

    def make() -> list[Constraint]:
        return [Hole.on_link(robot, q0, distance=0.08, link=link)
                for link in robot.constrained_links]

    starts = [pose.translation for pose in home_poses(robot, q0)]
    # two Lissajous curves, 4 cm across, in each tip's vertical plane facing forward (x, z):
    # measured along the reference run, the stacked rows [A; J_e1; J_e2] keep their 15th
    # singular value above 0.01 and the joint speeds under 6 % of their limits. Sideways
    # (y) motion of 1.5 cm or more takes the arms' r joints near 0, where they lose rank.
    tips = [lissajous(starts[0], (0.02, 0.0, 0.02), (0.10, 0.0, 0.15), (0.0, 0.0, 0.5)),
            lissajous(starts[1], (0.02, 0.0, 0.02), (0.13, 0.0, 0.08), (0.0, 0.0, 1.0))]
    duration = 10.0
    return Plan(
        "bimanual-trocars", robot, q0, duration, make,
        tips_through_constraints(robot, q0, make(), tips, duration),
        description="sda10f_dual, a trocar 8 cm along each arm's link 6, both tips trace "
                    "their own 4 cm Lissajous curve, orientations as the trocars allow")


#: The wall ahead of the mobile base: its distance from the base's front (m), and how far
#: the EE targets move forward (m), beyond what the arms reach from the base at the wall.
WALL_CLEARANCE, REACH_FORWARD = 0.25, 0.6


def _mobile_wall(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    base = link_placement(robot, q0, "mobile_base")
    front = 0.4  # half the 0.8 m base: its corners at x = +-0.4, y = +-0.3 (base frame)
    wall_point = base.act(np.array([front + WALL_CLEARANCE, 0.0, 0.0]))
    facing = base.rotation @ np.array([-1.0, 0.0, 0.0])  # the allowed side: behind the wall

    def make() -> list[Constraint]:
        return [Barrier("mobile_base", [front, side, 0.0], wall_point, facing)
                for side in (0.3, -0.3)]

    starts = home_poses(robot, q0)
    forward = base.rotation @ np.array([REACH_FORWARD, 0.0, 0.0])

    def target(t: float) -> list[pin.SE3]:
        advance = smoothstep(t / 6.0) * forward
        return [pin.SE3(start.rotation, start.translation + advance) for start in starts]

    return Plan(
        "mobile-wall", robot, q0, 10.0, make, target,
        description=f"sda10f_dual_mobile, both EE targets move {REACH_FORWARD:g} m forward, "
                    f"beyond the arms' reach; a wall {WALL_CLEARANCE:g} m ahead of the base's "
                    "front corners (barriers) stops the base")


#: The moves of ``fast-lateral``: (start s, duration s, sideways m, along the shaft m), each
#: a quintic (:func:`smoothstep`) whose peak speed is 15/8 of its mean: the 4 cm sweep in
#: 0.375 s peaks at 0.2 m/s, the 2 cm ones in 0.1875 s too; the 3 cm insertion in 0.3 s
#: peaks at 0.19 m/s.
FAST_LATERAL_MOVES = ((0.2, 0.1875, 0.02, 0.0), (0.4875, 0.375, -0.04, 0.0),
                      (0.9625, 0.1875, 0.02, 0.0), (1.4, 0.3, 0.0, 0.03), (2.0, 0.3, 0.0, -0.03))

#: Where ``fast-lateral`` puts its hole along the constrained link of a built-in robot (m);
#: another robot's: :func:`placement`.
FAST_LATERAL_HOLE_DISTANCE = {"sda10f": 0.08, "ur5_instrument": 0.2}


def _fast_lateral(robot: Robot) -> Plan:
    """Sideways sweeps of the tip at up to 0.2 m/s through the trocar, then a quick
    insertion and withdrawal along the shaft (:data:`FAST_LATERAL_MOVES`), the tip's
    orientation held: the instrument pivots in the hole as fast as the operator moves."""
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0)
    shaft = link_placement(robot, q0, robot.constrained_link).rotation @ robot.link_axis
    across = np.cross(shaft, [0.0, 0.0, 1.0])
    if np.linalg.norm(across) < 0.1:  # a vertical shaft: sideways is along world y
        across = np.cross(shaft, [1.0, 0.0, 0.0])
    across /= np.linalg.norm(across)
    own = robot.name if robot.name in FAST_LATERAL_HOLE_DISTANCE else "sda10f"
    where = placement(robot, own, FAST_LATERAL_HOLE_DISTANCE[own])
    distance = where.hole_distance

    def target(t: float) -> pin.SE3:
        offset = np.zeros(3)
        for begin, length, sideways, along in FAST_LATERAL_MOVES:
            offset += smoothstep((t - begin) / length) * where.scale * (
                sideways * across + along * shaft)
        return pin.SE3(start.rotation, start.translation + offset)

    return Plan(
        "fast-lateral", robot, q0, 2.6,
        lambda: [Hole.on_link(robot, q0, distance=distance)],
        target,
        description=f"{robot.name}, hole on the constrained link: the tip sweeps 4 cm sideways "
                    "at up to 0.2 m/s, then a quick 3 cm insertion and back"
        if robot.name in FAST_LATERAL_HOLE_DISTANCE
        else _elsewhere(robot, where, "the tip sweeps sideways, then a quick insertion and back"))


def _elsewhere(robot: Robot, where, motion: str) -> str:
    """A portable scenario's description on a robot it was not written for."""
    return (f"{robot.name}, hole {where.hole_distance * 100:.3g} cm along {robot.constrained_link} "
            f"(EE {robot.ee_frame}), paths x{where.scale:.2f} (reach): {motion}")


# ------------------------------------------------------------ with collision avoidance


def collision_settings(robot: Robot, obstacles: Sequence = ()) -> dict:
    """What a scenario declares (docs/design.md 18.6): self-collision and ``obstacles``
    with the damper's default distances and speed (``CollisionAvoidance.to_dict()``)."""
    return CollisionAvoidance(robot, obstacles).to_dict()


def moving_tips(starts: Sequence[np.ndarray], moves: Sequence[np.ndarray], begin: float,
                length: float) -> list[Callable[[float], np.ndarray]]:
    """Each tip's path: from its start, ``moves[i]`` (m) over ``length`` s from ``begin``
    (a quintic, :func:`smoothstep`), then held."""
    def path(start: np.ndarray, move: np.ndarray) -> Callable[[float], np.ndarray]:
        return lambda t: start + smoothstep((t - begin) / length) * move

    return [path(start, np.asarray(move, dtype=float)) for start, move in zip(starts, moves)]


#: How far (m) each tip of ``bimanual-crossing`` moves towards the other's side: the tips
#: start 0.27 m apart along y, their targets end 5 cm past each other (and 4 cm apart in z).
CROSSING_MOVE = np.array([0.0, 0.16, 0.0])


#: Where ``bimanual-crossing`` puts each arm's trocar: on the wrist link, this far along it (m)
#: (on link 5, as in ``bimanual-trocars``, the tips cannot move sideways: the r joints
#: reach 0, where the arms lose rank).
CROSSING_HOLE_LINK, CROSSING_HOLE_DISTANCE = "link_6_b", 0.05


def _bimanual_crossing(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()

    def make() -> list[Constraint]:
        return [Hole.on_link(robot, q0, distance=CROSSING_HOLE_DISTANCE,
                             link=f"arm_{side}_{CROSSING_HOLE_LINK}")
                for side in ("left", "right")]

    starts = [pose.translation for pose in home_poses(robot, q0)]
    # the left tip (+y) goes right and 2 cm down, the right tip left and 2 cm up: the
    # instruments, pivoting in their trocars, would pass through each other
    tips = moving_tips(starts, [-CROSSING_MOVE + [0.0, 0.0, -0.02],
                                CROSSING_MOVE + [0.0, 0.0, 0.02]], 0.5, 3.0)
    duration = 5.0
    return Plan(
        "bimanual-crossing", robot, q0, duration, make,
        tips_through_constraints(robot, q0, make(), tips, duration),
        description="sda10f_dual, a trocar on each wrist, the two tips' targets cross 16 cm "
                    "towards each other: the arms must stay apart (self-collision)",
        collisions=collision_settings(robot))


#: The organ of ``obstacle``: a sphere of this radius (m), its centre this far below the
#: tip (m): 2 cm below the instrument's collision capsule (3 cm in radius about the tip).
ORGAN_RADIUS, ORGAN_DEPTH = 0.03, 0.08


def _obstacle(robot: Robot) -> Plan:
    q0 = robot.q_home.copy()
    start = home_pose(robot, q0).translation
    organ = Sphere(start - [0.0, 0.0, ORGAN_DEPTH], ORGAN_RADIUS, name="organ")

    def make() -> list[Constraint]:
        return [Hole.on_link(robot, q0, distance=0.08)]

    duration = 5.0
    # the tip's target goes 5 cm down, through the organ's top, then 3 cm sideways
    tips = [lambda t: start + smoothstep((t - 0.5) / 2.0) * np.array([0.0, 0.0, -0.05])
            + smoothstep((t - 2.5) / 2.0) * np.array([0.0, 0.03, 0.0])]
    target = tips_through_constraints(robot, q0, make(), tips, duration)
    return Plan(
        "obstacle", robot, q0, duration, make, lambda t: target(t)[0],
        description=f"sda10f, trocar held, the tip's target goes 5 cm down into an organ "
                    f"(a {100 * ORGAN_RADIUS:g} cm sphere 2 cm below the instrument), then "
                    "sideways",
        collisions=collision_settings(robot, [organ]))


#: ``mobile-obstacles``: the gap (m) between the mobile base's sides and the obstacles
#: beside it, and between its front and the pole ahead.
MOBILE_CLEARANCE = 0.03


def _mobile_obstacles(robot: Robot) -> Plan:
    """The obstacles touch the base's box at an edge or a point, not face to face: a
    damper row holds one witness point, and two parallel faces turning against each
    other close at the far end of the face (docs/design.md 18.6)."""
    q0 = robot.q_home.copy()
    base = link_placement(robot, q0, "mobile_base")
    half_length, half_width = 0.4, 0.3  # the base's box (base frame)
    edge, post, height = 0.2, 0.05, 0.5  # a square box's edge, a post's radius (m)
    turned = base.rotation @ pin.rpy.rpyToMatrix(0.0, 0.0, math.pi / 4.0)
    obstacles = [
        Box(base.act(np.array([0.0, half_width + MOBILE_CLEARANCE + edge / math.sqrt(2.0),
                               0.5 * height])),
            [edge, edge, height], pin.rpy.matrixToRpy(turned), name="left box"),
        Capsule(base.act(np.array([0.0, -(half_width + MOBILE_CLEARANCE + post), 0.5])),
                post, 0.8, name="right post"),
        Capsule(base.act(np.array([half_length + MOBILE_CLEARANCE + post, 0.0, 0.5])),
                post, 0.8, name="pole")]

    def make() -> list[Constraint]:
        return [Hole.on_link(robot, q0, distance=0.08, link=link)
                for link in robot.constrained_links]

    starts = [pose.translation for pose in home_poses(robot, q0)]
    # both tips sweep together 8 cm to each side and 5 cm forward: the whole body,
    # base included, moves between the boxes, the pole ahead
    sway = [lissajous(start, (0.05, 0.08, 0.0), (0.1, 0.15, 0.0), (0.0, 0.0, 0.0))
            for start in starts]
    duration = 8.0
    return Plan(
        "mobile-obstacles", robot, q0, duration, make,
        tips_through_constraints(robot, q0, make(), sway, duration),
        description=f"sda10f_dual_mobile, a trocar on each arm, both tips sway 8 cm sideways "
                    f"and 5 cm forward; a box (its edge) and a post {100 * MOBILE_CLEARANCE:g} "
                    "cm beside the base, a pole ahead of it",
        collisions=collision_settings(robot, obstacles))


#: scenario name -> (robot name, builder)
SCENARIOS: dict[str, tuple[str, Callable[[Robot], Plan]]] = {
    "paper-hole": ("sda10f", _paper_hole),
    "paper-plane": ("sda10f", _paper_plane),
    "trocar-circle": ("ur5_instrument", _trocar_circle),
    "insertion": ("ur5_instrument", _insertion),
    "moving-trocar": ("ur5_instrument", _moving_trocar),
    "near-singular": ("sda10f", _near_singular),
    "joint-limits": ("ur5_instrument", _joint_limits),
    "barrier": ("ur5_instrument", _barrier),
    "multi": ("sda10f", _multi),
    "bimanual-trocars": ("sda10f_dual", _bimanual_trocars),
    "mobile-wall": ("sda10f_dual_mobile", _mobile_wall),
    "fast-lateral": ("sda10f", _fast_lateral),
    "bimanual-crossing": ("sda10f_dual", _bimanual_crossing),
    "obstacle": ("sda10f", _obstacle),
    "mobile-obstacles": ("sda10f_dual_mobile", _mobile_obstacles),
}


#: The scenarios that run on any single arm with a constrained link (:mod:`.placement`,
#: docs/design.md section 15.4.1).
PORTABLE_SCENARIOS = ("paper-hole", "trocar-circle", "fast-lateral", "joint-limits")


def load_scenario(name: str, robot: Robot | None = None) -> Plan:
    """The :class:`Plan` of a named scenario on its own robot or on ``robot`` (a single
    arm for :data:`PORTABLE_SCENARIOS`; the others run on their own robot only); unknown
    names list the known ones."""
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}; scenarios: {', '.join(SCENARIOS)}")
    robot_name, build = SCENARIOS[name]
    if robot is not None and robot.name != robot_name:
        if name not in PORTABLE_SCENARIOS:
            raise ValueError(f"scenario {name!r} runs on {robot_name} only; on another robot: "
                             f"{', '.join(PORTABLE_SCENARIOS)}")
        if robot.task_size != 6:
            raise ValueError(f"scenario {name!r} drives one end effector; robot {robot.name!r} "
                             f"has {len(robot.ee_frames)}")
    return build(robot or load_robot(robot_name))
