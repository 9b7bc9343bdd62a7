"""The example-robot-data arms the project is tried on, with a hole link each, and an
independent measure of their conditioning (Pinocchio and SciPy only, not
``teleop.robots.home``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.linalg import null_space

from teleop import Robot, load_robot
from teleop.robots.catalog import example_robot_data_share


@dataclass(frozen=True)
class ExampleArm:
    """A URDF of example-robot-data, what ``load_robot`` needs for a hole on one of its
    links, and the DoF that hole leaves the EE: the joints before the link less the hole's
    2 rows, plus the joints after it (a rank, at most 6)."""

    urdf: str
    ee_frame: str
    constrained_link: str
    link_axis: tuple[float, float, float]  # towards the next joint, link coordinates
    free_dof: int

    def load(self, **options) -> Robot:
        share = example_robot_data_share()
        return load_robot(share / "example-robot-data/robots" / self.urdf, ee_frame=self.ee_frame,
                          constrained_link=self.constrained_link, link_axis=self.link_axis,
                          package_dirs=[str(share)], **options)


EXAMPLE_ARMS = {
    # 4 joints before the forearm, 3 after (the fingers move nothing of the hand)
    "panda": ExampleArm("panda_description/urdf/panda.urdf", "panda_hand", "panda_link4",
                        (-0.0825, 0.384, 0.0), 5),
    # 3 before the forearm, 3 after
    "ur5": ExampleArm("ur_description/urdf/ur5_robot.urdf", "tool0", "forearm_link",
                      (0.0, 0.0, 1.0), 4),
    "xarm7": ExampleArm("xarm_description/urdf/xarm7.urdf", "link_eef", "link4",
                        (0.0775, -0.3425, 0.0), 5),
    # continuous joints 1, 4 and 6 (cos, sin): nq 9, nv 6; 3 before link 3, 3 after
    "kinova": ExampleArm("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector",
                         "j2s6s200_link_3", (0.0, 0.2073, -0.0114), 4),
}


def bounded_margins(model: pin.Model, q: np.ndarray) -> dict[str, float]:
    """Each revolute or prismatic joint with finite limits: its distance to the nearer
    bound as a share of its range."""
    margins = {}
    for joint in range(1, model.njoints):
        i = model.idx_qs[joint]
        lower, upper = model.lowerPositionLimit[i], model.upperPositionLimit[i]
        if model.nqs[joint] == 1 and abs(lower) < 1e10 and abs(upper) < 1e10:
            margins[model.names[joint]] = min(q[i] - lower, upper - q[i]) / (upper - lower)
    return margins


def singular_values(robot: Robot, q: np.ndarray, distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Singular values of the EE Jacobian ``J_e`` (LOCAL) and of ``J_e N``, ``N`` the joint
    velocities that move the point ``distance`` m along the constrained link only along
    the link (world-aligned point velocity, projected across the link axis)."""
    model, data = robot.model, robot.model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    ee = pin.getFrameJacobian(model, data, model.getFrameId(robot.ee_frame), pin.LOCAL)
    link = model.getFrameId(robot.constrained_link)
    rotation = data.oMf[link].rotation
    jacobian = pin.getFrameJacobian(model, data, link, pin.LOCAL_WORLD_ALIGNED)
    arm = rotation @ (distance * robot.link_axis)  # frame origin -> point, world
    point = jacobian[:3] + np.cross(jacobian[3:].T, arm).T  # v + w x r, column by column
    across = null_space((rotation @ robot.link_axis)[None, :]).T  # 2 world directions
    admissible = null_space(across @ point)
    return (np.linalg.svd(ee, compute_uv=False),
            np.linalg.svd(ee @ admissible, compute_uv=False))
