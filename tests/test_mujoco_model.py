"""The MuJoCo model of a URDF (``controllers.mujoco_model``, docs/design.md 4.8) against
Pinocchio, on its own: no mink, no controller.

* at random configurations, MuJoCo's forward kinematics puts every added site at
  Pinocchio's ``oMf`` of its frame: on fixed-base robots, on a planar mobile base and on
  the Panda with its (prismatic) fingers locked, which the builder makes fixed joints;
* the joint map round-trips configurations and velocities, and the site Jacobians in
  MuJoCo's columns are Pinocchio's frame Jacobians mapped by ``columns_to_mujoco``;
* a joint the builder cannot map is refused with a ``ValueError`` naming it.
"""

from __future__ import annotations

import warnings

import mujoco
import numpy as np
import pinocchio as pin
import pytest
from example_robots import EXAMPLE_ARMS, example_robot_data_share
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from controllers.mujoco_model import build_mujoco_model, site_name
from teleop import load_robot

SEEDS = st.integers(0, 2**32 - 1)
PROPERTY = settings(max_examples=25, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])

#: Site poses against ``oMf`` (m, and the rotation matrices' entries). Both are
#: compositions of the same ~20 rigid placements in double precision (rounding ~1e-16
#: each, times lever arms of a few metres: ~1e-14); the site's quaternion and a locked
#: joint's ``rpy`` are written from doubles. 1e-12 leaves a margin of 100 over that, while
#: any wrong placement, axis or joint order is off by millimetres or more.
POSE_TOLERANCE = 1e-12

#: Jacobian columns (m/s and rad/s per unit joint velocity): MuJoCo's ``mj_jacSite``
#: against Pinocchio's frame Jacobian, the same rounding as the poses.
JACOBIAN_TOLERANCE = 1e-12


def panda_fingers_locked():
    """The Panda of example-robot-data with its two prismatic fingers locked."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # meshes: not needed here
        return load_robot(
            example_robot_data_share() / "example-robot-data/robots/panda_description/urdf/panda.urdf",
            ee_frame="panda_hand", constrained_link="panda_link7", link_axis=(0, 0, 1),
            package_dirs=[str(example_robot_data_share())],
            q_home=[0.2, -0.3, 0.1, -2.0, 0.2, 1.8, 0.7, 0.02, 0.03],
            locked_joints=["panda_finger_joint1", "panda_finger_joint2"])


ROBOTS = {
    "sda10f": lambda: load_robot("sda10f"),
    "ur5_instrument": lambda: load_robot("ur5_instrument"),
    "sda10f_dual_mobile": lambda: load_robot("sda10f_dual_mobile"),
    "panda_fingers_locked": panda_fingers_locked,
    # continuous joints 1, 4 and 6: (cos, sin) in Pinocchio, an angle in MuJoCo
    "kinova": lambda: EXAMPLE_ARMS["kinova"].load(),
}


@pytest.fixture(scope="module", params=sorted(ROBOTS))
def built(request):
    """The robot, the frames given sites (every link and every EE), the MuJoCo model and
    the joint map."""
    robot = ROBOTS[request.param]()
    frames = [f.name for f in robot.model.frames if f.type == pin.FrameType.BODY]
    frames += [robot.model.frames[robot.model.getFrameId(name)].name for name in robot.ee_frames]
    mj_model, joints = build_mujoco_model(robot.model, robot.urdf_path.read_text(), frames,
                                          getattr(robot, "locked_joints", None))
    return robot, frames, mj_model, joints


def mujoco_data(mj_model: mujoco.MjModel, q_mj: np.ndarray) -> mujoco.MjData:
    data = mujoco.MjData(mj_model)
    data.qpos[:] = q_mj
    mujoco.mj_kinematics(mj_model, data)
    mujoco.mj_comPos(mj_model, data)  # (what mj_jacSite needs besides the kinematics)
    return data


def site_pose(mj_model: mujoco.MjModel, data: mujoco.MjData, frame: str) -> pin.SE3:
    site = mj_model.site(site_name(frame)).id
    return pin.SE3(data.site_xmat[site].reshape(3, 3).copy(), data.site_xpos[site].copy())


def test_the_model_has_pinocchios_joints(built):
    robot, frames, mj_model, joints = built
    # (cos, sin) in Pinocchio, an angle in MuJoCo: the planar heading, each continuous joint
    planar = 0 if joints.base is None else 1
    continuous = sum(1 for j in range(1, robot.model.njoints)
                     if robot.model.nqs[j] == 2 and robot.model.nvs[j] == 1)
    assert (mj_model.nq, mj_model.nv) == (robot.model.nq - planar - continuous, robot.model.nv)
    names = [robot.model.names[j] for j in range(1, robot.model.njoints)
             if robot.model.nvs[j] == 1]
    assert list(joints.names) == names
    assert all(mj_model.site(site_name(frame)).id >= 0 for frame in frames)


@PROPERTY
@given(seed=SEEDS)
def test_sites_sit_at_pinocchios_frames_at_random_configurations(built, seed):
    robot, frames, mj_model, joints = built
    q = robot.random_configuration(np.random.default_rng(seed))
    data = mujoco_data(mj_model, joints.q_to_mujoco(q, out=np.empty(mj_model.nq)))
    reference = robot.model.createData()
    pin.framesForwardKinematics(robot.model, reference, q)
    for frame in frames:
        expected = reference.oMf[robot.model.getFrameId(frame)]
        np.testing.assert_allclose(site_pose(mj_model, data, frame).homogeneous,
                                   expected.homogeneous, rtol=0.0, atol=POSE_TOLERANCE,
                                   err_msg=frame)


@PROPERTY
@given(seed=SEEDS)
def test_site_jacobians_are_pinocchios_in_mujocos_columns(built, seed):
    """``mj_jacSite`` (world-aligned, at the site) equals Pinocchio's
    ``LOCAL_WORLD_ALIGNED`` frame Jacobian with its columns mapped to MuJoCo's velocity."""
    robot, frames, mj_model, joints = built
    rng = np.random.default_rng(seed)
    q = robot.random_configuration(rng)
    q_mj = joints.q_to_mujoco(q, out=np.empty(mj_model.nq))
    data = mujoco_data(mj_model, q_mj)
    reference = robot.model.createData()
    pin.computeJointJacobians(robot.model, reference, q)
    pin.updateFramePlacements(robot.model, reference)
    for frame in (robot.ee_frames[0], frames[rng.integers(len(frames))]):
        expected = pin.getFrameJacobian(robot.model, reference, robot.model.getFrameId(frame),
                                        pin.LOCAL_WORLD_ALIGNED)
        linear, angular = np.zeros((3, mj_model.nv)), np.zeros((3, mj_model.nv))
        mujoco.mj_jacSite(mj_model, data, linear, angular, mj_model.site(site_name(frame)).id)
        np.testing.assert_allclose(np.vstack([linear, angular]),
                                   joints.columns_to_mujoco(expected, q_mj),
                                   rtol=0.0, atol=JACOBIAN_TOLERANCE, err_msg=frame)


@PROPERTY
@given(seed=SEEDS)
def test_the_joint_map_round_trips(built, seed):
    robot, _, mj_model, joints = built
    rng = np.random.default_rng(seed)
    q = robot.random_configuration(rng)
    v = rng.normal(size=robot.model.nv)
    q_mj = joints.q_to_mujoco(q, out=np.empty(mj_model.nq))
    np.testing.assert_allclose(joints.q_to_pinocchio(q_mj, out=np.empty(robot.model.nq)), q,
                               rtol=0.0, atol=1e-15)
    np.testing.assert_allclose(joints.v_to_pinocchio(joints.v_to_mujoco(v, q_mj), q_mj), v,
                               rtol=0.0, atol=1e-15)


def test_a_joint_it_cannot_map_is_refused_by_name():
    """A floating joint between two links (MuJoCo allows a free joint at the root only)."""
    urdf = """<robot name="floating"><link name="base"/>
      <link name="a"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"
        ixy="0" ixz="0" iyz="0"/></inertial></link>
      <link name="b"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"
        ixy="0" ixz="0" iyz="0"/></inertial></link>
      <joint name="hinge" type="revolute"><parent link="base"/><child link="a"/>
        <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
      <joint name="loose" type="floating"><parent link="a"/><child link="b"/></joint>
    </robot>"""
    model = pin.buildModelFromXML(urdf)
    with pytest.raises(ValueError, match="joint 'loose'.*JointModelFreeFlyer"):
        build_mujoco_model(model, urdf, [])
