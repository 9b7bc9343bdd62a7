"""Where a scenario puts its hole and how large it draws its path on a robot other than
the one it was written for (docs/design.md section 15.4.1): the hole halfway along the
constrained link towards what follows it on the way to the end effector, the path scaled
by the robot's reach over the scenario's own robot's."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from teleop.robots import Robot, load_robot

#: The shortest run of the constrained link's axis towards the end effector (m) a hole is
#: placed on: a link whose axis points elsewhere needs ``--link-axis``.
MIN_LINK_RUN = 0.02


@dataclass(frozen=True)
class Placement:
    """A scenario's hole distance along the constrained link (m) and the factor its path
    lengths are multiplied by."""

    hole_distance: float
    scale: float


def _frames_after(robot: Robot, q: np.ndarray) -> tuple[pin.Data, int, int]:
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data, model.getFrameId(robot.constrained_link), model.getFrameId(robot.ee_frame)


def link_run(robot: Robot, q: np.ndarray) -> float:
    """How far (m) along the constrained link's axis the link reaches towards the end
    effector: to the origin of the first joint after it on the path to the EE, else to
    the EE frame."""
    model = robot.model
    data, link, ee = _frames_after(robot, q)
    link_joint = model.frames[link].parentJoint
    path = list(model.supports[model.frames[ee].parentJoint])
    following = path[path.index(link_joint) + 1:] if link_joint in path else []
    end = data.oMi[following[0]].translation if following else data.oMf[ee].translation
    placement = data.oMf[link]
    return float(robot.link_axis @ placement.actInv(end))


def reach(robot: Robot, q: np.ndarray) -> float:
    """The length (m) of the chain to the EE at ``q``: the distances between the origins of
    its consecutive moving joints, then to the EE (what the arm spans stretched out)."""
    model = robot.model
    data, _, ee = _frames_after(robot, q)
    path = [j for j in model.supports[model.frames[ee].parentJoint] if model.nvs[j] > 0]
    points = [data.oMi[j].translation for j in path] + [data.oMf[ee].translation]
    return float(sum(np.linalg.norm(b - a) for a, b in zip(points, points[1:])))


def placement(robot: Robot, own_robot: str, own_distance: float) -> Placement:
    """The scenario's own numbers on its own robot (``own_robot``, the hole ``own_distance``
    along the link, scale 1); on another: the hole halfway along :func:`link_run`, the
    path scaled by :func:`reach` over the own robot's (a length that does not depend on
    the configuration). ``ValueError`` for a robot without a constrained link or one
    whose axis does not run towards the EE."""
    if robot.name == own_robot:
        return Placement(own_distance, 1.0)
    if robot.constrained_link is None:
        raise ValueError(f"robot {robot.name!r} has no constrained link for the scenario's hole: "
                         "give --constrained-link")
    run = link_run(robot, robot.q_home)
    if run < MIN_LINK_RUN:
        raise ValueError(f"the axis {robot.link_axis.tolist()} of {robot.constrained_link} runs "
                         f"{run * 1e3:.1f} mm towards {robot.ee_frame} (at least "
                         f"{MIN_LINK_RUN * 1e3:g} mm to place a hole on it): give --link-axis")
    own = load_robot(own_robot)
    return Placement(0.5 * run, reach(robot, robot.q_home) / reach(own, own.q_home))
