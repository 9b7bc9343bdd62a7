"""The two-arm SDA10F models, built straight from their URDF files with Pinocchio.

``sda10f_dual``: torso + left arm reproduce the shipped one-arm ``sda10f``; the right arm is
its mirror image across the torso's x-z plane (ROS-Industrial's ``reflect=-1``), so equal
joint values give mirror poses. ``sda10f_dual_mobile``: the same on a mobile base, loaded
with a planar root joint (x, y, heading: nq = 19, nv = 18).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

ROBOTS = Path(__file__).resolve().parents[1] / "teleop" / "robots"
ARM = ("1_s", "2_l", "3_e", "4_u", "5_r", "6_b", "7_t")
SIDES = ("left", "right")

#: home of one arm (the shipped sda10f home with joint L at 0.9 instead of 1.3: at 1.3 the
#: left tool crosses the sagittal plane, y = -0.07, so the mirrored right arm would hit it)
ARM_HOME = (0.0, 0.9, 0.8, -1.1, 0.5, -1.2, 0.6)
Q_HOME_DUAL = (0.0, *ARM_HOME, *ARM_HOME)
Q_HOME_MOBILE = (0.0, 0.0, 1.0, 0.0, *Q_HOME_DUAL)
#: each arm's constrained link and its axis (from joint R towards the wrist), link coordinates
LINK_AXIS = {"left": (0.0, 0.0, -1.0), "right": (0.0, 0.0, -1.0)}
#: height of base_link (torso axis) above the mobile base's frame (floor level)
TORSO_HEIGHT = 1.2

#: reflection across the torso's x-z plane (world), and across the link's y-z plane (local)
M = np.diag([1.0, -1.0, 1.0])
N = np.diag([-1.0, 1.0, 1.0])

SETTINGS = settings(max_examples=30, deadline=None)


def build(name: str, root_joint=None) -> pin.Model:
    path = str(ROBOTS / name)
    return pin.buildModelFromUrdf(path) if root_joint is None else pin.buildModelFromUrdf(path, root_joint)


SINGLE = build("sda10f.urdf")
DUAL = build("sda10f_dual.urdf")
MOBILE = build("sda10f_dual_mobile.urdf", pin.JointModelPlanar())


def placements(model: pin.Model, q: np.ndarray) -> pin.Data:
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data


def oMf(model: pin.Model, data: pin.Data, frame: str) -> pin.SE3:
    assert model.existFrame(frame), frame
    return data.oMf[model.getFrameId(frame)]


def mirrored(X: pin.SE3) -> np.ndarray:
    """The placement whose frame is the mirror image of X (x axis flipped to stay right-handed)."""
    H = np.eye(4)
    H[:3, :3] = M @ X.rotation @ N
    H[:3, 3] = M @ X.translation
    return H


def joint_values(lo, hi):
    return st.tuples(*(st.floats(float(a), float(b), allow_nan=False) for a, b in zip(lo, hi)))


def arm_values(model: pin.Model, side: str):
    idx = [model.joints[model.getJointId(f"arm_{side}_joint_{k}")].idx_q for k in ARM]
    return joint_values(model.lowerPositionLimit[idx], model.upperPositionLimit[idx]).map(np.array)


TORSO = st.floats(-2.967, 2.967, allow_nan=False)
LEFT, RIGHT = arm_values(DUAL, "left"), arm_values(DUAL, "right")


# ------------------------------------------------------------------ structure

def test_dual_joint_order_and_limits():
    names = ["torso_joint_b1"] + [f"arm_{s}_joint_{k}" for s in SIDES for k in ARM]
    assert list(DUAL.names)[1:] == names
    assert (DUAL.nq, DUAL.nv) == (15, 15)
    assert [DUAL.joints[i].idx_q for i in range(1, 16)] == list(range(15))
    # torso + each arm: the shipped model's position and velocity limits, same on both arms
    for s in SIDES:
        idx = [0] + [DUAL.joints[DUAL.getJointId(f"arm_{s}_joint_{k}")].idx_q for k in ARM]
        np.testing.assert_array_equal(DUAL.lowerPositionLimit[idx], SINGLE.lowerPositionLimit)
        np.testing.assert_array_equal(DUAL.upperPositionLimit[idx], SINGLE.upperPositionLimit)
        np.testing.assert_array_equal(DUAL.velocityLimit[idx], SINGLE.velocityLimit)
    for s in SIDES:
        for link in (f"arm_{s}_link_tool0", f"arm_{s}_link_5_r"):
            assert DUAL.existFrame(link) and MOBILE.existFrame(link)


def test_home_configurations():
    for model, q in ((DUAL, Q_HOME_DUAL), (MOBILE, Q_HOME_MOBILE)):
        q = np.array(q)
        assert q.shape == (model.nq,)
        assert np.all(q >= model.lowerPositionLimit) and np.all(q <= model.upperPositionLimit)
        assert pin.isNormalized(model, q)
    data = placements(DUAL, np.array(Q_HOME_DUAL))
    for frame in ("arm_%s_link_tool0", "arm_%s_link_5_r"):
        left, right = oMf(DUAL, data, frame % "left"), oMf(DUAL, data, frame % "right")
        np.testing.assert_allclose(right.homogeneous, mirrored(left), atol=1e-9)
    # the tools on their own side of the sagittal plane, in front of the torso
    assert oMf(DUAL, data, "arm_left_link_tool0").translation[1] > 0.1
    assert oMf(DUAL, data, "arm_left_link_tool0").translation[0] > 0.5


def test_home_keeps_the_arms_apart():
    """Collision shapes at home: arm to arm and arm to torso more than 5 cm apart.

    The two joint-S housings (link_1_s) are left out: their axes are collinear through the
    torso, 5.5 cm apart, and their primitive shapes overlap whatever the configuration.
    """
    model, collision, _ = pin.buildModelsFromUrdf(str(ROBOTS / "sda10f_dual.urdf"))
    owner = [model.frames[g.parentFrame].name for g in collision.geometryObjects]

    def part(link):
        return "left" if "_left_" in link else "right" if "_right_" in link else "torso"

    for i in range(len(owner)):
        for j in range(i + 1, len(owner)):
            a, b = owner[i], owner[j]
            if part(a) == part(b):
                continue
            if "link_1_s" in a or "link_1_s" in b:
                if part(a) != "torso" and part(b) != "torso" and "link_1_s" in a and "link_1_s" in b:
                    continue
                if "torso" in (part(a), part(b)):
                    continue  # joint S sits on the torso
            collision.addCollisionPair(pin.CollisionPair(i, j))
    assert len(collision.collisionPairs) > 100
    geometry = pin.GeometryData(collision)
    pin.updateGeometryPlacements(model, model.createData(), collision, geometry, np.array(Q_HOME_DUAL))
    pin.computeDistances(collision, geometry)
    distances = [r.min_distance for r in geometry.distanceResults]
    assert min(distances) > 0.05


# ------------------------------------------------------------------ (a) left arm = shipped sda10f

@SETTINGS
@given(TORSO, LEFT, RIGHT)
def test_left_arm_reproduces_the_shipped_sda10f(torso, left, right):
    single = placements(SINGLE, np.r_[torso, left])
    dual = placements(DUAL, np.r_[torso, left, right])
    pairs = [("tool0", "arm_left_link_tool0"), ("arm_link_5_r", "arm_left_link_5_r"),
             ("torso_link", "torso_link_b1")] + [(f"arm_link_{k}", f"arm_left_link_{k}") for k in ARM]
    for a, b in pairs:
        np.testing.assert_allclose(oMf(DUAL, dual, b).homogeneous, oMf(SINGLE, single, a).homogeneous,
                                   rtol=0, atol=1e-12, err_msg=b)


def test_left_arm_geometry_is_the_shipped_geometry():
    """Same primitive shapes at the same places (the torso gains the right shoulder's cylinder)."""
    _, single, _ = pin.buildModelsFromUrdf(str(ROBOTS / "sda10f.urdf"))
    _, dual, _ = pin.buildModelsFromUrdf(str(ROBOTS / "sda10f_dual.urdf"))
    by_name = {g.name: g for g in dual.geometryObjects}
    for g in single.geometryObjects:
        name = g.name.replace("arm_link", "arm_left_link").replace("torso_link", "torso_link_b1")
        h = by_name[name]
        assert type(h.geometry) is type(g.geometry), name
        np.testing.assert_array_equal(h.placement.homogeneous, g.placement.homogeneous)
    shared = sum(1 for g in single.geometryObjects if "arm_" not in g.name)  # base and torso
    assert len(dual.geometryObjects) == 2 * len(single.geometryObjects) - shared + 1


# ------------------------------------------------------------------ (b) mirror symmetry

@SETTINGS
@given(TORSO, LEFT, RIGHT)
def test_right_arm_is_the_mirror_image_of_the_left(torso, a, b):
    """(t, a, b) and (-t, b, a) are mirror images: each arm's frames mirror the other's."""
    data = placements(DUAL, np.r_[torso, a, b])
    image = placements(DUAL, np.r_[-torso, b, a])
    frames = ["link_tool0", "link_5_r"] + [f"link_{k}" for k in ARM]
    for f in frames:
        for s, t in (("left", "right"), ("right", "left")):
            np.testing.assert_allclose(oMf(DUAL, image, f"arm_{t}_{f}").homogeneous,
                                       mirrored(oMf(DUAL, data, f"arm_{s}_{f}")),
                                       rtol=0, atol=1e-12, err_msg=f"{s} -> {t} {f}")


@SETTINGS
@given(TORSO, LEFT)
def test_right_arm_shapes_mirror_the_left(torso, a):
    model, collision, _ = pin.buildModelsFromUrdf(str(ROBOTS / "sda10f_dual.urdf"))
    geometry = pin.GeometryData(collision)
    pin.updateGeometryPlacements(model, model.createData(), collision, geometry, np.r_[0.0, a, a])
    names = [g.name for g in collision.geometryObjects]
    for i, name in enumerate(names):
        if "arm_left_" in name:
            j = names.index(name.replace("arm_left_", "arm_right_"))
            np.testing.assert_allclose(geometry.oMg[j].homogeneous, mirrored(geometry.oMg[i]),
                                       rtol=0, atol=1e-12, err_msg=name)


@SETTINGS
@given(TORSO, LEFT, RIGHT)
def test_link_axes_point_from_joint_r_to_the_wrist(torso, a, b):
    data = placements(DUAL, np.r_[torso, a, b])
    for s in SIDES:
        link = oMf(DUAL, data, f"arm_{s}_link_5_r")
        axis = link.rotation @ np.array(LINK_AXIS[s])
        # joint B lies on the axis (0.155 m along it, 8 mm off); the tool beyond it, whatever B
        for towards, cosine in ((f"arm_{s}_link_6_b", 0.998), (f"arm_{s}_link_tool0", 0.1)):
            d = oMf(DUAL, data, towards).translation - link.translation
            assert axis @ d > cosine * np.linalg.norm(d), (s, towards)
    # mirror images of each other when the configurations are
    image = placements(DUAL, np.r_[-torso, b, a])
    left = oMf(DUAL, data, "arm_left_link_5_r").rotation @ np.array(LINK_AXIS["left"])
    right = oMf(DUAL, image, "arm_right_link_5_r").rotation @ np.array(LINK_AXIS["right"])
    np.testing.assert_allclose(right, M @ left, atol=1e-12)


# ------------------------------------------------------------------ (c) the mobile robot

HEADING = st.floats(-np.pi, np.pi, allow_nan=False).filter(lambda t: t > -np.pi)
XY = st.floats(-3.0, 3.0, allow_nan=False)


def mobile_q(x, y, theta, torso, a, b) -> np.ndarray:
    return np.r_[x, y, np.cos(theta), np.sin(theta), torso, a, b]


MOBILE_FRAMES = tuple(f"arm_{s}_{f}" for s in SIDES for f in ("link_tool0", "link_5_r"))


def test_mobile_model_structure():
    assert (MOBILE.nq, MOBILE.nv) == (19, 18)
    root = MOBILE.joints[1]
    assert root.shortname() == "JointModelPlanar" and (root.nq, root.nv) == (4, 3)
    assert MOBILE.names[1] == "root_joint"
    # the root joint's child body is the mobile base, with the robot fixed on it
    bodies = [f for f in MOBILE.frames if f.parentJoint == 1 and f.type == pin.FrameType.BODY]
    assert bodies[0].name == "mobile_base"
    assert {"mobile_base", "base_link"} <= {f.name for f in bodies}
    assert list(MOBILE.names)[2:] == list(DUAL.names)[1:]
    for name in DUAL.names[1:]:
        i, j = DUAL.getJointId(name), MOBILE.getJointId(name)
        assert MOBILE.joints[j].idx_q == DUAL.joints[i].idx_q + 4
        assert MOBILE.joints[j].idx_v == DUAL.joints[i].idx_v + 3


@SETTINGS
@given(TORSO, LEFT, RIGHT)
def test_mobile_robot_is_the_dual_robot_on_its_base(torso, a, b):
    data = placements(MOBILE, mobile_q(0.0, 0.0, 0.0, torso, a, b))
    dual = placements(DUAL, np.r_[torso, a, b])
    lift = pin.SE3(np.eye(3), np.array([0.0, 0.0, TORSO_HEIGHT]))
    for f in MOBILE_FRAMES + ("base_link", "torso_link_b1"):
        np.testing.assert_allclose(oMf(MOBILE, data, f).homogeneous,
                                   (lift * oMf(DUAL, dual, f)).homogeneous, rtol=0, atol=1e-12)


@SETTINGS
@given(XY, XY, HEADING, TORSO, LEFT, RIGHT)
def test_base_placement_moves_the_robot_rigidly(x, y, theta, torso, a, b):
    moved = placements(MOBILE, mobile_q(x, y, theta, torso, a, b))
    still = placements(MOBILE, mobile_q(0.0, 0.0, 0.0, torso, a, b))
    base = pin.SE3(pin.exp3(np.array([0.0, 0.0, theta])), np.array([x, y, 0.0]))
    np.testing.assert_allclose(oMf(MOBILE, moved, "mobile_base").homogeneous, base.homogeneous,
                               rtol=0, atol=1e-12)
    for f in MOBILE_FRAMES + ("base_link", "arm_left_link_3_e", "arm_right_link_7_t"):
        np.testing.assert_allclose(oMf(MOBILE, moved, f).homogeneous,
                                   (base * oMf(MOBILE, still, f)).homogeneous, rtol=0, atol=1e-12)


@SETTINGS
@given(XY, XY, HEADING, TORSO, LEFT, RIGHT)
def test_mobile_local_jacobians_match_finite_differences(x, y, theta, torso, a, b):
    """LOCAL frame Jacobians against central differences through pin.integrate (nq != nv)."""
    q = mobile_q(x, y, theta, torso, a, b)
    data = MOBILE.createData()
    pin.computeJointJacobians(MOBILE, data, q)
    pin.updateFramePlacements(MOBILE, data)
    h = 1e-6
    for f in MOBILE_FRAMES:
        fid = MOBILE.getFrameId(f)
        J = pin.getFrameJacobian(MOBILE, data, fid, pin.LOCAL)
        assert J.shape == (6, 18)
        X = data.oMf[fid].copy()
        numeric = np.empty((6, MOBILE.nv))
        for k in range(MOBILE.nv):
            dv = np.zeros(MOBILE.nv)
            dv[k] = h
            plus = placements(MOBILE, pin.integrate(MOBILE, q, dv))
            minus = placements(MOBILE, pin.integrate(MOBILE, q, -dv))
            numeric[:, k] = (pin.log6(X.actInv(plus.oMf[fid])).vector
                             - pin.log6(X.actInv(minus.oMf[fid])).vector) / (2 * h)
        np.testing.assert_allclose(J, numeric, rtol=0, atol=1e-6, err_msg=f)


def test_planar_heading_is_not_a_configuration_coordinate():
    """A heading step through pin.integrate turns (cos, sin); the base frame turns with it."""
    q = np.array(Q_HOME_MOBILE)
    v = np.zeros(MOBILE.nv)
    v[2] = 0.3
    q1 = pin.integrate(MOBILE, q, v)
    np.testing.assert_allclose(q1[:4], [0.0, 0.0, np.cos(0.3), np.sin(0.3)], atol=1e-15)
    base = oMf(MOBILE, placements(MOBILE, q1), "mobile_base")
    np.testing.assert_allclose(base.rotation, pin.exp3(np.array([0.0, 0.0, 0.3])), atol=1e-15)


@pytest.mark.parametrize("name", ["sda10f_dual.urdf", "sda10f_dual_mobile.urdf"])
def test_primitive_geometry_only(name):
    _, collision, visual = pin.buildModelsFromUrdf(str(ROBOTS / name))
    for g in list(collision.geometryObjects) + list(visual.geometryObjects):
        assert g.meshPath in ("BOX", "CYLINDER", "SPHERE"), (g.name, g.meshPath)
        assert type(g.geometry).__name__ in ("Box", "Cylinder", "Sphere"), g.name
