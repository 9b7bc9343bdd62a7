"""A MuJoCo model of a Pinocchio robot's URDF, with a site at each frame asked for
(docs/design.md 4.8, 11.3, 14).

The MuJoCo peer (:mod:`controllers.mink`) solves on it; a MuJoCo physics plant can
simulate it. Both then move the same joints, matched by name (:class:`JointMap`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

import mujoco
import numpy as np
import pinocchio as pin

from .collision_geoms import add_collision_geoms
from .joint_map import JointMap, PlanarBase
from .kinematic_urdf import kinematic_urdf

#: Prefix of the MuJoCo sites added for the Pinocchio frames (``site_name``).
SITE_PREFIX = "pin:"


def site_name(frame_name: str) -> str:
    """Name of the MuJoCo site added at the Pinocchio frame ``frame_name``."""
    return SITE_PREFIX + frame_name


#: Pinocchio's planar joint (``JointModelPlanar``): the one multi-dof joint supported, as
#: the root joint of a mobile base.
_PLANAR = "JointModelPlanar"

#: Pinocchio's unbounded revolute joints (``JointModelRUBX``, ...): ``(cos, sin)``, nv 1.
_CONTINUOUS = "JointModelRUB"

#: Names given to the MuJoCo joints of a planar root joint: suffixes to its Pinocchio name.
PLANAR_SUFFIXES = (":x", ":y", ":heading")


def build_mujoco_model(
    model: pin.Model, urdf_text: str, frames: Iterable[str],
    locked_joints: Mapping[str, Sequence[float]] | None = None,
    geometry: pin.GeometryModel | None = None,
) -> tuple[mujoco.MjModel, JointMap]:
    """Compile :func:`mujoco_spec` and map its joints to ``model``'s (:func:`joint_map`)."""
    mj_model = mujoco_spec(model, urdf_text, frames, locked_joints, geometry).compile()
    return mj_model, joint_map(model, mj_model)


def mujoco_spec(
    model: pin.Model, urdf_text: str, frames: Iterable[str],
    locked_joints: Mapping[str, Sequence[float]] | None = None,
    geometry: pin.GeometryModel | None = None,
) -> mujoco.MjSpec:
    """A MuJoCo spec of the URDF with a site at each Pinocchio frame in ``frames``, not yet
    compiled (a physics plant adds its actuators and payload before compiling).

    MuJoCo merges the bodies joined by fixed joints (``fusestatic``) and drops frames
    that carry no body, so the end effectors and the constraint links are added back as
    sites *before* compiling. A Pinocchio frame's ``placement`` is relative to its parent
    joint frame, which is the frame of that joint's child link: MuJoCo's body holding
    the joint of the same name (or the world body for frames fixed to the base). The
    site's pose in that body is that placement.

    A planar root joint (``load_robot(..., root_joint="planar")``) becomes three joints
    of the URDF's root body, in this order: a slide along world x, a slide along world y
    and a hinge about the body's z axis through its origin, named after the Pinocchio
    joint (:data:`PLANAR_SUFFIXES`). The root body then sits at
    ``Trans(x, y) Rz(th)``, Pinocchio's planar placement; :class:`PlanarBase` maps the
    coordinates.

    ``locked_joints`` (the robot's, joint name to its Pinocchio coordinates) are made
    fixed at those positions, as ``model`` has them.

    ``geometry`` (a Pinocchio ``GeometryModel`` of ``model``, objects on joint 0 fixed in
    the world), if given, becomes geoms for distances only (:func:`add_collision_geoms`);
    the URDF's own collision and visual elements are always dropped.

    Raises ``ValueError`` naming a joint of ``model`` that is not in the URDF or has more
    than one degree of freedom (other than a planar root joint); :func:`joint_map` checks
    the rest.
    """
    spec = mujoco.MjSpec.from_string(kinematic_urdf(urdf_text, locked_joints or {}))
    # massless links are fine for kinematics: bound mass/inertia so that they compile
    spec.compiler.boundmass = 1e-6
    spec.compiler.boundinertia = 1e-9
    bodies = {}
    for j in range(1, model.njoints):
        name = model.names[j]
        if _is_planar_root(model, j):
            bodies[j] = _add_planar_base(spec, model, name)
            continue
        if model.nvs[j] != 1:
            raise ValueError(
                f"joint {name!r}: only 1-dof revolute/prismatic joints, continuous joints and "
                f"a planar root joint are supported (Pinocchio {model.joints[j].shortname()}, "
                f"nq={model.nqs[j]}, nv={model.nvs[j]})")
        joint = spec.joint(name)
        if joint is None:
            raise ValueError(f"joint {name!r} of the Pinocchio model is not in the MuJoCo model")
        bodies[j] = joint.parent
    for frame_name in dict.fromkeys(frames):  # unique, in order
        frame = model.frames[model.getFrameId(frame_name)]
        body = spec.worldbody if frame.parentJoint == 0 else bodies[frame.parentJoint]
        placement = frame.placement
        quaternion = pin.Quaternion(placement.rotation)
        body.add_site(
            name=site_name(frame_name),
            pos=placement.translation.copy(),
            quat=[quaternion.w, quaternion.x, quaternion.y, quaternion.z],
        )
    if geometry is not None:
        spec.compiler.discardvisual = False  # it would drop geoms that take no contacts
        add_collision_geoms(spec, geometry, bodies)
    return spec


def _add_planar_base(spec: mujoco.MjSpec, model: pin.Model, name: str) -> mujoco.MjsBody:
    """Give the URDF's root body the slide x, slide y, hinge z of the planar joint ``name``."""
    root = spec.worldbody.first_body()
    if root is None or spec.worldbody.next_body(root) is not None:
        raise ValueError("a planar root joint needs a URDF with exactly one root link")
    if not (model.existFrame(root.name) and model.frames[model.getFrameId(root.name)]
            .placement.isIdentity()):
        raise ValueError(f"the URDF's root link {root.name!r} is not the frame of Pinocchio's "
                         f"planar joint {name!r}")
    kinds = (mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_HINGE)
    axes = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0])
    for joint_name, kind, axis in zip(_mujoco_names(model, model.getJointId(name)), kinds, axes):
        if spec.joint(joint_name) is not None:
            raise ValueError(f"the URDF already has a joint named {joint_name!r}")
        root.add_joint(name=joint_name, type=kind, axis=axis,
                       limited=mujoco.mjtLimited.mjLIMITED_FALSE)
    return root


def _is_planar_root(model: pin.Model, joint: int) -> bool:
    return model.joints[joint].shortname() == _PLANAR and model.parents[joint] == 0


def _mujoco_names(model: pin.Model, joint: int) -> list[str]:
    """Names of the MuJoCo joints that stand for Pinocchio's joint ``joint``."""
    name = model.names[joint]
    return [name + suffix for suffix in PLANAR_SUFFIXES] if _is_planar_root(model, joint) else [name]


def joint_map(model: pin.Model, mj_model: mujoco.MjModel) -> JointMap:
    """The :class:`JointMap` between ``model`` and a MuJoCo model compiled from
    :func:`mujoco_spec` of it (``ValueError`` when their joints differ)."""
    scalar = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    mj_names = [mj_model.joint(i).name for i in range(mj_model.njnt)]
    pin_names = [n for j in range(1, model.njoints) for n in _mujoco_names(model, j)]
    if sorted(mj_names) != sorted(pin_names):
        raise ValueError(
            f"joints differ between Pinocchio {pin_names} and MuJoCo {mj_names}")
    names, pin_q, pin_v, mj_q, mj_v = [], [], [], [], []
    continuous_pin_q, continuous_mj_q = [], []
    base = None
    for j in range(1, model.njoints):
        name = model.names[j]
        if _is_planar_root(model, j):
            x, y, heading = (mj_model.joint(n).id for n in _mujoco_names(model, j))
            if not (mj_model.jnt_dofadr[y] == mj_model.jnt_dofadr[x] + 1
                    and mj_model.jnt_dofadr[heading] == mj_model.jnt_dofadr[x] + 2):
                raise ValueError(f"the MuJoCo joints of the planar joint {name!r} are not "
                                 "consecutive")
            base = PlanarBase(pin_q=int(model.idx_qs[j]), pin_v=int(model.idx_vs[j]),
                              mj_q=int(mj_model.jnt_qposadr[x]), mj_v=int(mj_model.jnt_dofadr[x]))
            continue
        jid = mj_model.joint(name).id
        if (model.joints[j].shortname().startswith(_CONTINUOUS) and model.nvs[j] == 1
                and int(mj_model.jnt_type[jid]) == int(mujoco.mjtJoint.mjJNT_HINGE)):
            names.append(name)
            pin_v.append(model.idx_vs[j])
            mj_v.append(mj_model.jnt_dofadr[jid])
            continuous_pin_q.append(model.idx_qs[j])
            continuous_mj_q.append(mj_model.jnt_qposadr[jid])
            continue
        if model.nqs[j] != 1 or model.nvs[j] != 1 or int(mj_model.jnt_type[jid]) not in scalar:
            raise ValueError(
                f"joint {name!r}: only 1-dof revolute/prismatic joints, continuous joints "
                f"and a planar root joint are supported (Pinocchio nq={model.nqs[j]}, nv={model.nvs[j]}, "
                f"MuJoCo type {mujoco.mjtJoint(int(mj_model.jnt_type[jid])).name})")
        names.append(name)
        pin_q.append(model.idx_qs[j])
        pin_v.append(model.idx_vs[j])
        mj_q.append(mj_model.jnt_qposadr[jid])
        mj_v.append(mj_model.jnt_dofadr[jid])
    # (cos, sin) in Pinocchio, an angle in MuJoCo: the heading and each continuous joint
    angle_coordinates = (0 if base is None else 1) + len(continuous_pin_q)
    if mj_model.nq != model.nq - angle_coordinates or mj_model.nv != model.nv:
        raise ValueError(f"MuJoCo nq/nv = {mj_model.nq}/{mj_model.nv}, "
                         f"Pinocchio {model.nq}/{model.nv}")
    pin_qs, pin_vs, mj_qs, mj_vs = (np.array(i, dtype=int) for i in (pin_q, pin_v, mj_q, mj_v))
    identity = bool(base is None and not continuous_pin_q
                    and np.array_equal(pin_qs, mj_qs) and np.array_equal(pin_vs, mj_vs)
                    and np.array_equal(pin_qs, np.arange(model.nq))
                    and np.array_equal(pin_vs, np.arange(model.nv)))
    return JointMap(tuple(names), pin_qs, pin_vs, mj_qs, mj_vs, identity, base,
                    np.array(continuous_pin_q, dtype=int), np.array(continuous_mj_q, dtype=int))

