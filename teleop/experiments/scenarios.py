"""Named, deterministic operator trajectories for comparing controllers.

A scenario builds a :class:`Plan`: the robot, the start configuration, fresh constraint
objects (each controller run gets its own, since a moving hole is mutated), the operator
target ``T*(t)`` and, for moving geometry, what moves at time ``t``. Every trajectory
starts at the EE's home pose with zero velocity (smooth ramps), so no controller is
handed a step.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from constraints import Barrier, Constraint, Hole, Plane
from teleop.robots import Robot, load_robot

from .plan import Plan, home_pose, link_placement, smoothstep


def operator_motion(start: pin.SE3, amplitude: Sequence[float], frequencies: Sequence[float],
                    angle_amplitude: float, ramp: float = 2.5) -> Callable[[float], pin.SE3]:
    """Smooth, operator-like 3D motion: incommensurate sinusoids in position and attitude.

    Position offsets (world frame) ``A_i sin(2 pi f_i t)``; attitude wobble of
    ``angle_amplitude`` rad about a slowly turning axis; both faded in over ``ramp`` s.
    """
    amplitude = np.asarray(amplitude, dtype=float)
    frequencies = np.asarray(frequencies, dtype=float)

    def target(t: float) -> pin.SE3:
        envelope = smoothstep(t / ramp)
        offset = envelope * amplitude * np.sin(2.0 * np.pi * frequencies * t)
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
    return Plan(
        "paper-hole", robot, q0, 10.0,
        lambda: [Hole.on_link(robot, q0, distance=0.08)],
        operator_motion(start, *PAPER_MOTION),
        description="sda10f, hole on link 6 (6 joints before, 2 after), operator-like 3D motion")


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
    radius, period = 0.03, 4.0

    def target(t: float) -> pin.SE3:
        r = radius * smoothstep(t / 1.5)  # spiral out from the home tip position
        phase = 2.0 * math.pi * t / period
        offset = np.array([r * math.cos(phase), r * math.sin(phase), 0.0])
        return pin.SE3(start.rotation, start.translation + offset)

    return Plan(
        "trocar-circle", robot, q0, 10.0,
        lambda: [Hole.on_link(robot, q0, distance=0.2)],
        target,
        description="ur5_instrument, trocar on the shaft, the tip traces a 3 cm circle")


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

    def target(t: float) -> pin.SE3:
        angle = 1.7 * smoothstep(t / 5.0)  # the wrist pitch limit is 1.4 rad
        return pin.SE3(start.rotation @ pin.exp3(np.array([angle, 0.0, 0.0])), start.translation)

    return Plan(
        "joint-limits", robot, q0, 10.0,
        lambda: [Hole.on_link(robot, q0, distance=0.2)],
        target,
        description="ur5_instrument, the target pitches the tip 1.7 rad: the wrist limit is 1.4")


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
}


def load_scenario(name: str, robot: Robot | None = None) -> Plan:
    """The :class:`Plan` of a named scenario; unknown names list the known ones."""
    if name not in SCENARIOS:
        raise ValueError(f"unknown scenario {name!r}; scenarios: {', '.join(SCENARIOS)}")
    robot_name, build = SCENARIOS[name]
    return build(robot or load_robot(robot_name))
