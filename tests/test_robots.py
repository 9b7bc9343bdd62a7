"""Robot-model layer: shipped URDFs against docs/design.md section 6, load_robot behaviour,
the home pose of any URDF (section 6.1)."""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest
from example_robots import EXAMPLE_ARMS, bounded_margins, singular_values
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from teleop import BUILTIN_ROBOTS, Robot, load_robot
from teleop.robots.home import HomeWarning, check_home

# docs/design.md section 6, typed in: joint, origin xyz, origin rpy, axis, limit, velocity.
SDA10F_TABLE = [
    ("torso_joint_b1", (0, 0, 0), (0, 0, 0), (0, 0, 1), 2.967, 2.269),
    ("arm_joint_1_s", (0.09996, 0.0275, 0.32214), (1.57, 0, 0), (0, 0, -1), 3.13, 2.95),
    ("arm_joint_2_l", (0, 0.0577, -0.2255), (-1.57, 0, 0), (0, 0, -1), 1.90, 2.95),
    ("arm_joint_3_e", (0, 0.1690, -0.0454), (1.57, 0, 0), (0, 0, -1), 2.95, 2.95),
    ("arm_joint_4_u", (0, -0.0085, -0.181), (-1.57, 0, 0), (0, 0, 1), 2.36, 2.95),
    ("arm_joint_5_r", (0, 0.1936, 0.0155), (1.57, 0, 0), (0, 0, 1), 3.13, 3.48),
    ("arm_joint_6_b", (0, 0.0080, -0.155), (-1.57, 0, 0), (0, 0, 1), 1.90, 3.48),
    ("arm_joint_7_t", (0, 0.168, -0.015), (1.57, 0, 0), (0, 0, -1), 3.13, 6.97),
]

UR5_D = [0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823]
UR5_A = [0.0, -0.425, -0.39225, 0.0, 0.0, 0.0]
UR5_ALPHA = [np.pi / 2, 0.0, 0.0, np.pi / 2, -np.pi / 2, 0.0]


@pytest.fixture(scope="module", params=sorted(BUILTIN_ROBOTS))
def robot(request) -> Robot:
    return load_robot(request.param)


@pytest.fixture(scope="module")
def sda10f() -> Robot:
    return load_robot("sda10f")


@pytest.fixture(scope="module")
def ur5() -> Robot:
    return load_robot("ur5_instrument")


def local_jacobian(robot: Robot, q: np.ndarray, frame: str) -> np.ndarray:
    data = robot.model.createData()
    pin.computeJointJacobians(robot.model, data, q)
    pin.updateFramePlacements(robot.model, data)
    return pin.getFrameJacobian(robot.model, data, robot.model.getFrameId(frame), pin.LOCAL)


def placement(robot: Robot, q: np.ndarray, frame: str) -> pin.SE3:
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(frame)]


def dh_forward(theta: np.ndarray) -> np.ndarray:
    """Standard DH product T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i), written out."""
    T = np.eye(4)
    for th, d, a, al in zip(theta, UR5_D, UR5_A, UR5_ALPHA):
        ct, st, ca, sa = np.cos(th), np.sin(th), np.cos(al), np.sin(al)
        T = T @ np.array([[ct, -st * ca, st * sa, a * ct],
                          [st, ct * ca, -ct * sa, a * st],
                          [0.0, sa, ca, d],
                          [0.0, 0.0, 0.0, 1.0]])
    return T


def pre_post_split(robot: Robot, link: str, ee_frame: str) -> tuple[int, int]:
    """(DoF supporting ``link``, DoF after it up to ``ee_frame``)."""
    model = robot.model
    link_joint = model.frames[model.getFrameId(link)].parentJoint
    ee_joint = model.frames[model.getFrameId(ee_frame)].parentJoint
    pre = [j for j in model.supports[link_joint] if j != 0]
    post = [j for j in model.supports[ee_joint] if j not in model.supports[link_joint]]
    return sum(model.nvs[j] for j in pre), sum(model.nvs[j] for j in post)


# ---------------------------------------------------------------- built-ins

#: (nq, nv) of each built-in robot; the mobile one's planar base has 4 and 3
SIZES = {"sda10f": (8, 8), "ur5_instrument": (8, 8), "sda10f_dual": (15, 15),
         "sda10f_dual_mobile": (19, 18)}


def test_builtins_load_with_geometry(robot: Robot) -> None:
    assert (robot.nq, robot.nv) == SIZES[robot.name]
    assert robot.visual_model.ngeoms > 0 and robot.collision_model.ngeoms > 0
    assert robot.urdf_path.is_file()
    assert np.isclose(np.linalg.norm(robot.link_axis), 1.0)
    with pytest.raises(ValueError):
        robot.q_home[0] = 1.0  # read-only
    with pytest.raises(ValueError):
        robot.link_axis[0] = 1.0
    for kind in (pin.GeometryType.VISUAL, pin.GeometryType.COLLISION):
        assert pin.buildGeomFromUrdf(robot.model, str(robot.urdf_path), kind).ngeoms > 0


def test_builtin_six_before_two_after(robot: Robot) -> None:
    """Each arm's trocar link has the paper's 6 DoF before it (9 on the mobile base: the
    planar joint's 3 too) and 2 after it, up to that arm's EE."""
    assert len(robot.constrained_links) == len(robot.ee_frames)
    before = 9 if robot.root_joint == "planar" else 6
    for link, ee_frame in zip(robot.constrained_links, robot.ee_frames):
        assert pre_post_split(robot, link, ee_frame) == (before, 2), link


def test_sda10f_matches_design_table(sda10f: Robot) -> None:
    model = sda10f.model
    data = model.createData()
    pin.forwardKinematics(model, data, np.zeros(model.nq))
    assert [model.names[i] for i in range(1, model.njoints)] == [row[0] for row in SDA10F_TABLE]
    for i, (name, xyz, rpy, axis, limit, vel) in enumerate(SDA10F_TABLE, start=1):
        M = model.jointPlacements[i]
        np.testing.assert_allclose(M.translation, xyz, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(M.rotation, pin.rpy.rpyToMatrix(*rpy), atol=1e-12, err_msg=name)
        np.testing.assert_allclose(np.asarray(data.joints[i].S).ravel()[3:], axis, atol=1e-12, err_msg=name)
        iq, iv = model.idx_qs[i], model.idx_vs[i]
        assert model.lowerPositionLimit[iq] == pytest.approx(-limit, abs=1e-12), name
        assert model.upperPositionLimit[iq] == pytest.approx(limit, abs=1e-12), name
        assert model.velocityLimit[iv] == pytest.approx(vel, abs=1e-12), name
    assert sda10f.constrained_link == "arm_link_5_r" and sda10f.ee_frame == "tool0"
    np.testing.assert_allclose(sda10f.link_axis, (0, 0, -1))


def test_sda10f_tool0_points_outward(sda10f: Robot) -> None:
    """tool0 sits 0.10 m beyond joint T, on the side away from joint B."""
    q = sda10f.q_home.copy()
    p_b = placement(sda10f, q, "arm_link_6_b").translation
    p_t = placement(sda10f, q, "arm_link_7_t").translation
    tool = placement(sda10f, q, "tool0")
    assert np.linalg.norm(tool.translation - p_t) == pytest.approx(0.10, abs=1e-12)
    assert np.dot(tool.translation - p_t, p_t - p_b) > 0
    assert np.dot(tool.rotation[:, 2], tool.translation - p_t) == pytest.approx(0.10, abs=1e-9)


def test_ur5_flange_matches_standard_dh(ur5: Robot) -> None:
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = ur5.random_configuration(rng, margin=0.0)
        T = placement(ur5, q, "flange").homogeneous
        np.testing.assert_allclose(T, dh_forward(q[:6]), atol=1e-12)


def test_ur5_instrument_chain(ur5: Robot) -> None:
    q = ur5.random_configuration(np.random.default_rng(3))
    flange = placement(ur5, q, "flange")
    shaft = placement(ur5, q, "instrument_shaft")
    assert shaft.isApprox(flange, 1e-12)
    pitch = placement(ur5, q, "wrist_pitch_link")
    np.testing.assert_allclose(shaft.actInv(pitch.translation), (0, 0, 0.40), atol=1e-12)
    tip = placement(ur5, np.r_[q[:6], 0.0, 0.0], "tool_tip")
    np.testing.assert_allclose(shaft.actInv(tip.translation), (0, 0, 0.429), atol=1e-12)
    model = ur5.model
    for name, limit, vel in [("shoulder_pan_joint", 2 * np.pi, 3.15), ("wrist_pitch_joint", 1.4, 3.0),
                             ("wrist_yaw_joint", 1.4, 3.0)]:
        j = model.getJointId(name)
        assert model.upperPositionLimit[model.idx_qs[j]] == pytest.approx(limit)
        assert model.velocityLimit[model.idx_vs[j]] == pytest.approx(vel)


@pytest.mark.parametrize("name, max_cond, min_sigma",
                         [("sda10f", 30.0, 0.05), ("ur5_instrument", 30.0, 0.01)])
def test_q_home_well_conditioned(name: str, max_cond: float, min_sigma: float) -> None:
    robot = load_robot(name)
    q = robot.q_home.copy()
    lo, hi = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    margin = 0.1 * (hi - lo)
    assert np.all(q > lo + margin) and np.all(q < hi - margin)
    J_link = local_jacobian(robot, q, robot.constrained_link)[:, :6]
    assert np.linalg.cond(J_link) < max_cond
    J_ee = local_jacobian(robot, q, robot.ee_frame)
    assert np.linalg.svd(J_ee, compute_uv=False)[-1] > min_sigma


def test_ur5_q_home_shaft_points_down_into_workspace(ur5: Robot) -> None:
    q = ur5.q_home.copy()
    shaft = placement(ur5, q, "instrument_shaft")
    tip = placement(ur5, q, "tool_tip").translation
    assert shaft.rotation[:, 2] @ np.array([0.0, 0.0, -1.0]) > 0.95
    assert 0.3 <= np.hypot(tip[0], tip[1]) <= 0.6
    assert tip[2] > -0.3


def test_random_configuration_inside_margin(robot: Robot) -> None:
    rng = np.random.default_rng(0)
    bounded = np.abs(robot.model.lowerPositionLimit) < 1e10  # not a planar base's
    lo, hi = robot.model.lowerPositionLimit[bounded], robot.model.upperPositionLimit[bounded]
    qs = np.array([robot.random_configuration(rng, margin=0.2) for _ in range(200)])
    assert np.all(qs[:, bounded] >= lo + 0.2 * (hi - lo))
    assert np.all(qs[:, bounded] <= hi - 0.2 * (hi - lo))
    if robot.root_joint == "planar":  # (x, y, cos, sin): a unit heading
        np.testing.assert_allclose(np.hypot(qs[:, 2], qs[:, 3]), 1.0, atol=1e-12)


def test_builtin_overrides() -> None:
    with pytest.warns(HomeWarning, match="singular"):  # the arm stretched out
        robot = load_robot("ur5_instrument", ee_frame="flange", link_axis=(0, 0, 5),
                           q_home=np.zeros(8))
    assert robot.ee_frame == "flange" and robot.ee_frame_id == robot.model.getFrameId("flange")
    np.testing.assert_allclose(robot.link_axis, (0, 0, 1))
    np.testing.assert_array_equal(robot.q_home, np.zeros(8))
    assert robot.constrained_link == "instrument_shaft"


@pytest.mark.parametrize("axis, direction", [((1e308, 1e308, 1e308), (1, 1, 1)),
                                             ((-1e308, 0, 3e307), (-10, 0, 3))])
def test_a_link_axis_is_normalised_whatever_its_length(axis, direction) -> None:
    """Its norm overflowed to infinity: a huge axis became (0, 0, 0), taken as valid."""
    robot = load_robot("ur5_instrument", link_axis=axis)
    np.testing.assert_allclose(robot.link_axis, np.array(direction) / np.linalg.norm(direction),
                               rtol=1e-15)


# ---------------------------------------------------------------- errors

def test_missing_file(tmp_path) -> None:
    path = tmp_path / "nowhere.urdf"
    with pytest.raises(FileNotFoundError, match="nowhere.urdf") as info:
        load_robot(path)
    assert "sda10f" in str(info.value) and "ur5_instrument" in str(info.value)


def test_bad_urdf_text(tmp_path) -> None:
    path = tmp_path / "broken.urdf"
    path.write_text('<robot name="x"><link name="a"></robot>')
    with pytest.raises(ValueError, match="broken.urdf"):
        load_robot(path)


def test_unknown_frames(sda10f: Robot) -> None:
    with pytest.raises(ValueError, match="no_such_frame") as info:
        load_robot("sda10f", ee_frame="no_such_frame")
    assert "tool0" in str(info.value)
    with pytest.raises(ValueError, match="no_such_link"):
        load_robot("sda10f", constrained_link="no_such_link")


@pytest.mark.parametrize("axis", [(0, 0, 0), (1, 0), (np.nan, 0, 1), "abc"])
def test_bad_link_axis(axis) -> None:
    with pytest.raises(ValueError, match="link_axis"):
        load_robot("sda10f", link_axis=axis)


@pytest.mark.parametrize("q_home, match", [
    (np.zeros(7), "size"),
    (np.r_[np.zeros(7), np.nan], "non-finite"),
    (np.r_[np.zeros(7), 4.0], "outside the position limits at indices \\[7\\]"),
])
def test_bad_q_home(q_home, match) -> None:
    with pytest.raises(ValueError, match=f"q_home.*{match}"):
        load_robot("sda10f", q_home=q_home)


# ---------------------------------------------------------------- custom URDFs

THREE_LINK = """<?xml version="1.0"?>
<robot name="three_link">
  <link name="l0"><visual><geometry><box size="0.1 0.1 0.1"/></geometry></visual></link>
  <link name="l1"><visual><geometry>{mesh}</geometry></visual></link>
  <link name="l2"/>
  <link name="l3"/>
  <joint name="j1" type="revolute"><parent link="l0"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="0.2" upper="1.0" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0.3 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j3" type="continuous"><parent link="l2"/><child link="l3"/><origin xyz="0.3 0 0"/>
    <axis xyz="0 1 0"/></joint>
</robot>
"""

TETRA_STL = """solid t
facet normal 0 0 -1
outer loop
vertex 0 0 0
vertex 0 0.1 0
vertex 0.1 0 0
endloop
endfacet
facet normal 1 1 1
outer loop
vertex 0.1 0 0
vertex 0 0.1 0
vertex 0 0 0.1
endloop
endfacet
endsolid t
"""


def test_custom_urdf_defaults(tmp_path) -> None:
    path = tmp_path / "three.urdf"
    path.write_text(THREE_LINK.format(mesh='<cylinder radius="0.02" length="0.3"/>'))
    robot = load_robot(str(path))
    assert robot.name == "three_link"
    assert robot.ee_frame == "l3"
    assert robot.ee_frame == [f.name for f in robot.model.frames if f.type == pin.FrameType.BODY][-1]
    assert robot.constrained_link is None and robot.constrained_frame_id is None
    np.testing.assert_allclose(robot.link_axis, (0, 0, 1))
    assert (robot.nq, robot.nv) == (4, 3)  # the continuous joint has nq = 2
    # j1 (0.2 to 1.0) 10 % of its range inside, j2 likewise, j3 a unit (cos, sin)
    assert 0.28 <= robot.q_home[0] <= 0.92 and -0.8 <= robot.q_home[1] <= 0.8
    assert np.hypot(robot.q_home[2], robot.q_home[3]) == pytest.approx(1.0, abs=1e-12)
    # the 3 joints move l3 in 3 independent directions, well conditioned
    assert np.linalg.svd(local_jacobian(robot, robot.q_home, "l3"), compute_uv=False)[2] > 0.1
    q = robot.random_configuration(np.random.default_rng(1))
    assert q.shape == (4,) and np.hypot(q[2], q[3]) == pytest.approx(1.0)
    robot = load_robot(path, ee_frame="l2", constrained_link="l1", link_axis=(1, 0, 0))
    assert robot.ee_frame == "l2" and robot.constrained_link == "l1"


def test_custom_urdf_package_meshes(tmp_path) -> None:
    (tmp_path / "share" / "mypkg" / "meshes").mkdir(parents=True)
    (tmp_path / "share" / "mypkg" / "meshes" / "t.stl").write_text(TETRA_STL)
    path = tmp_path / "elsewhere" / "three.urdf"
    path.parent.mkdir()
    path.write_text(THREE_LINK.format(mesh='<mesh filename="package://mypkg/meshes/t.stl"/>'))
    robot = load_robot(path, package_dirs=[tmp_path / "share"])
    assert robot.visual_model.ngeoms == 2
    with pytest.warns(UserWarning, match="mypkg/meshes/t.stl"):
        robot = load_robot(path)  # meshes not found: kinematics still load
    assert robot.visual_model.ngeoms == 0 and robot.model.nq == 4


# ---------------------------------------------------------------- home poses (section 6.1)

#: every bounded joint this share of its range from each bound (docs/design.md section 6.1)
HOME_MARGIN = 0.1
#: smallest singular value of J_e and of J_e N (over the rank the hole leaves) a home
#: must exceed: ten times the CJM's singular_threshold, where its damping starts
WELL_CONDITIONED = 0.1


@pytest.mark.parametrize("name", sorted(BUILTIN_ROBOTS))
def test_builtin_homes_are_the_hand_chosen_ones_inside_the_margin(name: str) -> None:
    robot = load_robot(name)
    np.testing.assert_array_equal(robot.q_home, BUILTIN_ROBOTS[name]["q_home"])
    assert min(bounded_margins(robot.model, robot.q_home).values()) >= HOME_MARGIN


@pytest.fixture(scope="module")
def example_arms() -> dict[str, Robot]:
    return {name: arm.load() for name, arm in EXAMPLE_ARMS.items()}


@pytest.mark.parametrize("name", sorted(EXAMPLE_ARMS))
def test_default_home_of_a_urdf_is_inside_the_margin_and_well_conditioned(example_arms, name):
    """The neutral pose clipped to the limits (the old default) is at a bound or singular
    for each; the default home is neither: its smallest singular values, measured here
    with Pinocchio and SciPy for a hole 8 cm along the link, are above 0.1."""
    robot, arm = example_arms[name], EXAMPLE_ARMS[name]
    q = robot.q_home
    assert min(bounded_margins(robot.model, q).values()) >= HOME_MARGIN - 1e-12  # rounding
    ee, constrained = singular_values(robot, q, 0.08)
    assert ee[5] > WELL_CONDITIONED and constrained[arm.free_dof - 1] > WELL_CONDITIONED
    assert constrained.size == arm.free_dof or constrained[arm.free_dof] < 1e-9  # the rank
    clipped = np.clip(pin.neutral(robot.model), robot.model.lowerPositionLimit,
                      robot.model.upperPositionLimit)
    ee, constrained = singular_values(robot, clipped, 0.08)
    assert (min(bounded_margins(robot.model, clipped).values()) == 0.0
            or min(ee[5], constrained[arm.free_dof - 1]) < 0.07)


def test_the_default_home_is_the_same_every_time(example_arms) -> None:
    np.testing.assert_array_equal(EXAMPLE_ARMS["ur5"].load().q_home, example_arms["ur5"].q_home)


def test_a_given_home_at_bounds_warns_once_naming_the_joints(example_arms) -> None:
    panda = example_arms["panda"]
    clipped = np.clip(pin.neutral(panda.model), panda.model.lowerPositionLimit,
                      panda.model.upperPositionLimit)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        robot = EXAMPLE_ARMS["panda"].load(q_home=clipped)
    homes = [w for w in caught if issubclass(w.category, HomeWarning)]
    assert len(homes) == 1
    message = str(homes[0].message)
    for joint in ("panda_joint4", "panda_joint6", "panda_finger_joint1"):
        assert joint in message
    assert "panda_joint1 " not in message
    assert homes[0].filename.endswith("example_robots.py")  # where load_robot was called
    np.testing.assert_array_equal(robot.q_home, clipped)  # taken all the same


def test_a_given_singular_home_warns_and_a_good_one_does_not(example_arms) -> None:
    with pytest.warns(HomeWarning, match="singular for a hole 0.08 m along forearm_link"):
        EXAMPLE_ARMS["ur5"].load(q_home=np.zeros(6))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the default home, given back (a scene does)
        EXAMPLE_ARMS["ur5"].load(q_home=example_arms["ur5"].q_home)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(shares=st.lists(st.floats(0.0, 1.0), min_size=7, max_size=7))
def test_check_home_warns_exactly_when_near_a_bound_or_singular(example_arms, shares) -> None:
    """Against the measure of this module: a joint within 10 % of its range of a bound, or
    a smallest singular value (EE, or EE with the hole) below the CJM's 0.01."""
    robot = example_arms["xarm7"]
    lower, upper = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    q = lower + np.array(shares) * (upper - lower)
    margin = min(bounded_margins(robot.model, q).values())
    ee, constrained = singular_values(robot, q, 0.08)
    sigma = min(ee[5], constrained[EXAMPLE_ARMS["xarm7"].free_dof - 1])
    assume(abs(margin - HOME_MARGIN) > 1e-6 and abs(sigma - 0.01) > 1e-6)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_home(robot, q)
    assert len(caught) == (1 if margin < HOME_MARGIN or sigma < 0.01 else 0)
