"""The outside peer: the same constrained teleoperation step posed to mink.

mink (differential IK on a MuJoCo model) is what a user would pick instead of writing a
controller. :class:`MinkController` poses *the same* problem as
:class:`controllers.QPController` to it, so the three controllers can be compared step
for step on the same robot, constraints and operator command.

Conventions of mink 1.3.0 (read from ``mink/solve_ik.py``, ``mink/tasks/task.py``,
``mink/tasks/frame_task.py``, ``mink/limits/*.py``), on which everything below rests:

* The QP variable is the tangent displacement ``dq = v dt`` (MuJoCo dof order), not the
  velocity; ``solve_ik`` returns ``v = dq / dt``, the velocity with which
  ``configuration.integrate(v, dt)`` moves.
* A task with error ``e(q)`` and Jacobian ``J = de/dq`` is a cost
  ``|cost * (J dq + gain e)|^2``; in ``constraints=[task]`` it is the hard equality
  ``J dq = -gain e`` (``gain`` must lie in [0, 1]).
* ``FrameTask``: ``e = log(T_b^-1 T_t)`` (a body twist, ``LOCAL``, linear first: the
  right-minus ``T_t (-) T_b``) and ``J = -Jlog(T_t^-1 T_b) J_b`` with ``J_b`` the body
  Jacobian of the frame (see :class:`MinkController` for why this tracks ``V`` exactly).
* A limit returns ``G dq <= h`` at step ``dt``. mink's own ``VelocityLimit``
  (``|dq| <= v_max dt``) and ``ConfigurationLimit`` (``gain (q_min - q) <= dq <=
  gain (q_max - q)``) have no common point once a joint is past a position limit by more
  than ``v_max dt / gain``; the controller uses the project's joint box instead
  (:class:`controllers.mink_joint_box.JointBoxLimit`).
* The global ``damping`` adds ``damping * I`` to the Hessian in ``dq``: since the whole
  objective scales as ``dt^2`` it acts like the QP controller's ``mu`` on ``v``.
* A planar root joint is MuJoCo's slide x, slide y, hinge z (:class:`PlanarBase`), which
  ``configuration.integrate`` moves by ``(x, y, th) + v dt`` where Pinocchio integrates
  the SE(2) exponential: the two agree to first order in ``dt``, and mink only uses the
  velocity, never the integrated configuration.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass

import mink
import mujoco
import numpy as np
import pinocchio as pin
import qpsolvers
from mink.limits.limit import Constraint as LimitRows

from constraints import Constraint
from constraints.validation import as_number, as_vector

from .base import EQUALITY_TOLERANCE, Controller, Kinematics, SolverError, StepStatus, as_twist_weight
from .joint_limits import DEFAULT_LIMIT_GAIN
from .least_residual import HeldRows, held_rows, least_residual_problem
from .linalg import DampingPolicy
from .mink_joint_box import JointBoxLimit
from .qp import (DAQP_PROXIMAL_FLOOR, DAQP_PROXIMAL_WEIGHT, INFINITE_BOUND, PROXQP_RHO,
                 SOLVER_SETTINGS, TASK_ACCURACY, ProxQPSolver, QuadraticProgram, held_note)
from .qp_budget import ITERATION_CAPS, BudgetExceeded, StepBudget, TimeBudget
from .task_damping import task_damping

#: Solver settings in the units of *velocity* (rad/s, m/s); they are multiplied by ``dt``
#: before they reach the backend, because mink's QP variable is ``dq = v dt``: a
#: tolerance of 1e-10 on ``v`` is 1e-13 on ``dq`` at 1 kHz. daqp is an active-set solver
#: whose equalities are exact to rounding; proxqp is asked for 1e-11 so that the
#: equality rows hold to 1e-9 m/s or better (measured 1e-14..1e-11); OSQP (ADMM, first
#: order) for 1e-7 with polishing (measured 1e-17 once polished), and its residual is
#: reported, not hidden.
VELOCITY_TOLERANCES: dict[str, dict[str, float]] = {
    "proxqp": {"eps_abs": 1e-11},
    "daqp": {"primal_tol": 1e-10},
    "osqp": {"eps_abs": 1e-7},
}

#: Settings passed as they are (no unit). ``eq_reduction=1`` makes daqp eliminate the
#: equality rows before it factorises the Hessian. Without it, mink's Hessian
#: ``J_e^T J_e + damping I`` (rank 6 + damping on 8 joints, damping 1e-12 by default) has
#: pivots below daqp's ``sing_tol`` (3.7e-11); daqp then switches to its automatic
#: proximal regularisation and stops 2e-5 to 3e-3 rad/s away from the solution (measured
#: on both built-in robots; exact again for damping >= 1e-11). ``raise_error=False``
#: keeps OSQP's failures as a "not found" status (and silences its deprecation warning).
FIXED_SETTINGS: dict[str, dict] = {
    "proxqp": {"eps_rel": 0.0},
    "daqp": {"eq_reduction": 1},
    "osqp": {"eps_rel": 0.0, "polishing": True, "max_iter": 20000, "raise_error": False},
}

#: Iteration caps of mink's solves: the QP controller's, but proxqp's. mink's QP
#: (``mink.build_ik``, in ``dq`` units, the posture's curvature ``c^2`` ~ 1e-10) is solved
#: by the QP controller's proxsuite objects (``ProxQPSolver``), which take both
#: ``max_iter`` and ``max_iter_in`` (``qpsolvers``' proxqp path takes no inner cap). After
#: the 5.5 cm hole jump on sda10f (tests/test_qp_recovery.py) 100 x 50 stopped 362 of 500
#: steps; 25 x 100 none (at most 22 outer, 423 inner iterations a solve), but with no margin
#: (a rounding difference put one step over it): 50 x 100. The worst step
#: it allows is measured in docs/design.md section 10.6.
MINK_ITERATION_CAPS: dict[str, dict[str, int]] = {
    **ITERATION_CAPS, "proxqp": {"max_iter": 50, "max_iter_in": 100}}

#: Cost of the posture task relative to the task's scale (``MinkController.posture_cost``:
#: mink's cost is ``c = posture_cost * sqrt(s)``). The posture bends the twist by about
#: ``c^2 / sigma^2``, and for ``c`` too small mink's solve no longer resolves the posture
#: (``c^2`` in ``dq`` units against tolerances of 1e-13). The choice is measured against
#: the CJM with no limit binding in docs/design.md section 10.
DEFAULT_POSTURE_COST = 1e-5

#: mink's ``damping`` without a posture task: it keeps mink's Hessian ``J_e^T J_e``
#: definite on a redundant robot. A posture task does that itself (``c^2 I``), and a
#: damping then pulls the redundancy towards zero with a weight ``damping / c^2``
#: (1e-12 against ``c = 1e-4``: 7e-6 rad/s off the CJM's posture on the Panda), so it
#: defaults to 0 there.
DEFAULT_DAMPING = 1e-12

#: Pinocchio's ``[x y z qx qy qz qw]`` re-ordered into mink's ``wxyz_xyz``.
_WXYZ_XYZ = np.array([6, 3, 4, 5, 0, 1, 2])

#: Prefix of the MuJoCo sites added for the Pinocchio frames (``site_name``).
SITE_PREFIX = "pin:"


# ----------------------------------------------------------------------------- model


@dataclass(frozen=True)
class PlanarBase:
    """Pinocchio's planar root joint as MuJoCo's slide x, slide y and hinge z on the root body.

    Pinocchio's configuration is ``(x, y, cos th, sin th)`` and its velocity
    ``(v_x, v_y, w)`` is in the *base* frame (``LOCAL``); MuJoCo's slides move along the
    world's axes, so its configuration is ``(x, y, th)`` and its velocity
    ``(x', y', th') = P(th) (v_x, v_y, w)`` with ``P(th) = diag(R(th), 1)``, ``R(th)`` the
    2D rotation (docs/design.md section 11). ``P`` is orthogonal: a matrix ``M`` acting on
    Pinocchio's base velocity acts on MuJoCo's as ``M P(th)^T``.

    Attributes: the first configuration and velocity index of the base in each model.
    """

    pin_q: int
    pin_v: int
    mj_q: int
    mj_v: int

    def heading(self, q_mj: np.ndarray) -> float:
        """The base's heading ``th`` (rad) in a MuJoCo ``qpos``."""
        return float(q_mj[self.mj_q + 2])

    def rotation(self, q_mj: np.ndarray) -> np.ndarray:
        """``P(th)`` (3 x 3): Pinocchio's base velocity to MuJoCo's."""
        heading = self.heading(q_mj)
        cos, sin = math.cos(heading), math.sin(heading)
        return np.array([[cos, -sin, 0.0], [sin, cos, 0.0], [0.0, 0.0, 1.0]])

    def q_to_mujoco(self, q_pin: np.ndarray, out: np.ndarray) -> None:
        """``(x, y, cos, sin)`` into ``(x, y, atan2(sin, cos))``."""
        x, y, cos, sin = q_pin[self.pin_q:self.pin_q + 4]
        out[self.mj_q:self.mj_q + 3] = x, y, math.atan2(sin, cos)

    def q_to_pinocchio(self, q_mj: np.ndarray, out: np.ndarray) -> None:
        """``(x, y, th)`` into ``(x, y, cos th, sin th)``."""
        x, y, heading = q_mj[self.mj_q:self.mj_q + 3]
        out[self.pin_q:self.pin_q + 4] = x, y, math.cos(heading), math.sin(heading)

    def v_to_pinocchio(self, v_mj: np.ndarray, q_mj: np.ndarray, out: np.ndarray) -> None:
        """Base-frame ``(v_x, v_y, w) = P^T (x', y', th')``."""
        out[self.pin_v:self.pin_v + 3] = self.rotation(q_mj).T @ v_mj[self.mj_v:self.mj_v + 3]

    def v_to_mujoco(self, v_pin: np.ndarray, q_mj: np.ndarray, out: np.ndarray) -> None:
        """World-frame ``(x', y', th') = P (v_x, v_y, w)``."""
        out[self.mj_v:self.mj_v + 3] = self.rotation(q_mj) @ v_pin[self.pin_v:self.pin_v + 3]

    def columns_to_mujoco(self, matrix_pin: np.ndarray, q_mj: np.ndarray,
                          out: np.ndarray) -> None:
        """The base's columns of ``matrix_pin`` times ``P^T``, into MuJoCo's base columns."""
        out[:, self.mj_v:self.mj_v + 3] = (
            matrix_pin[:, self.pin_v:self.pin_v + 3] @ self.rotation(q_mj).T)


@dataclass(frozen=True)
class JointMap:
    """Maps between Pinocchio and MuJoCo coordinates, joints matched by name.

    For every 1-dof joint ``k`` (revolute or prismatic): ``q_mj[mj_q[k]] = q_pin[pin_q[k]]``
    and ``v_mj[mj_v[k]] = v_pin[pin_v[k]]``. A planar root joint, if any, is ``base``
    (:class:`PlanarBase`): its velocity map turns with the heading, so the velocity and
    column maps take the MuJoCo configuration ``q_mj`` they apply at. Built-in fixed-base
    robots have 8 revolute joints in the same order in both models (``identity``, the
    maps then only copy), but nothing here assumes it.
    """

    names: tuple[str, ...]
    pin_q: np.ndarray
    pin_v: np.ndarray
    mj_q: np.ndarray
    mj_v: np.ndarray
    identity: bool
    base: PlanarBase | None = None

    def q_to_mujoco(self, q_pin: np.ndarray, out: np.ndarray) -> np.ndarray:
        """MuJoCo ``qpos`` from a Pinocchio configuration, written into ``out``."""
        if self.identity:
            out[:] = q_pin
            return out
        out[self.mj_q] = q_pin[self.pin_q]
        if self.base is not None:
            self.base.q_to_mujoco(q_pin, out)
        return out

    def q_to_pinocchio(self, q_mj: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Pinocchio configuration from a MuJoCo ``qpos``, written into ``out``."""
        if self.identity:
            out[:] = q_mj
            return out
        out[self.pin_q] = q_mj[self.mj_q]
        if self.base is not None:
            self.base.q_to_pinocchio(q_mj, out)
        return out

    def v_to_pinocchio(self, v_mj: np.ndarray, q_mj: np.ndarray) -> np.ndarray:
        """Pinocchio velocity from a MuJoCo one at ``q_mj`` (``v_mj`` itself when
        ``identity``)."""
        if self.identity:
            return v_mj
        out = np.empty(len(v_mj))  # nv is the same in both models
        out[self.pin_v] = v_mj[self.mj_v]
        if self.base is not None:
            self.base.v_to_pinocchio(v_mj, q_mj, out)
        return out

    def v_to_mujoco(self, v_pin: np.ndarray, q_mj: np.ndarray) -> np.ndarray:
        """MuJoCo velocity from a Pinocchio one at ``q_mj`` (``v_pin`` itself when
        ``identity``)."""
        if self.identity:
            return v_pin
        out = np.empty(len(v_pin))
        out[self.mj_v] = v_pin[self.pin_v]
        if self.base is not None:
            self.base.v_to_mujoco(v_pin, q_mj, out)
        return out

    def columns_to_mujoco(self, matrix_pin: np.ndarray, q_mj: np.ndarray) -> np.ndarray:
        """A matrix acting on Pinocchio velocities, made to act on MuJoCo ones at ``q_mj``:
        ``M_mj v_mj = M_pin v_pin`` (``matrix_pin`` itself when ``identity``)."""
        if self.identity:
            return matrix_pin
        out = np.empty_like(matrix_pin)
        out[:, self.mj_v] = matrix_pin[:, self.pin_v]
        if self.base is not None:
            self.base.columns_to_mujoco(matrix_pin, q_mj, out)
        return out


def site_name(frame_name: str) -> str:
    """Name of the MuJoCo site added at the Pinocchio frame ``frame_name``."""
    return SITE_PREFIX + frame_name


def _kinematic_urdf(urdf_text: str, locked_joints: Mapping[str, Sequence[float]]) -> str:
    """The URDF with its ``<visual>``/``<collision>`` elements removed and the locked joints
    made fixed.

    MuJoCo would otherwise try to load every mesh (``package://`` URIs it cannot
    resolve); only the kinematics matter to mink. Inertials are kept. A joint the robot
    was loaded with locked (``teleop.load_robot(..., locked_joints=...)``, Pinocchio's
    ``buildReducedModel``) becomes a fixed joint whose origin carries its motion at the
    locked position, so both models have the same joints and the same frames.
    """
    root = ET.fromstring(urdf_text)
    if root.tag != "robot":
        raise ValueError(f"not a URDF: root element is <{root.tag}>, expected <robot>")
    for link in root.iter("link"):
        for child in [c for c in link if c.tag in ("visual", "collision")]:
            link.remove(child)
    joints = {joint.get("name"): joint for joint in root.iter("joint")}
    for name, position in locked_joints.items():
        if name not in joints:
            raise ValueError(f"locked joint {name!r} is not in the URDF")
        _fix_joint(joints[name], position)
    for extension in [c for c in root if c.tag == "mujoco"]:
        root.remove(extension)
    compiler = ET.SubElement(ET.SubElement(root, "mujoco"), "compiler")
    compiler.set("discardvisual", "true")
    compiler.set("fusestatic", "true")
    return ET.tostring(root, encoding="unicode")


def _fix_joint(joint: ET.Element, position: Sequence[float]) -> None:
    """Turn a URDF ``<joint>`` into a fixed one at ``position`` (its Pinocchio coordinates:
    an angle, a displacement, or ``(cos, sin)`` for a continuous joint).

    The new origin is ``T_origin * T_motion(position)``: a rotation about the joint axis
    (revolute, continuous) or a translation along it (prismatic), in URDF conventions
    (``rpy`` is ``Rz(y) Ry(p) Rx(r)``, Pinocchio's ``rpyToMatrix``).
    """
    kind = joint.get("type")
    axis_element = joint.find("axis")
    axis = np.array([float(x) for x in (axis_element.get("xyz", "1 0 0") if axis_element is not None
                                        else "1 0 0").split()])
    axis /= np.linalg.norm(axis)
    values = [float(x) for x in position]
    if kind in ("revolute", "continuous"):
        angle = math.atan2(values[1], values[0]) if len(values) == 2 else values[0]
        motion = pin.SE3(pin.exp3(angle * axis), np.zeros(3))
    elif kind == "prismatic":
        motion = pin.SE3(np.eye(3), values[0] * axis)
    else:
        raise ValueError(f"joint {joint.get('name')!r}: locking a {kind!r} joint is not supported "
                         "(revolute, continuous and prismatic only)")
    origin_element = joint.find("origin")
    if origin_element is None:
        origin_element = ET.SubElement(joint, "origin")
    xyz = [float(x) for x in origin_element.get("xyz", "0 0 0").split()]
    rpy = [float(x) for x in origin_element.get("rpy", "0 0 0").split()]
    fixed = pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(xyz)) * motion
    origin_element.set("xyz", " ".join(repr(float(x)) for x in fixed.translation))
    origin_element.set("rpy", " ".join(repr(float(x)) for x in pin.rpy.matrixToRpy(fixed.rotation)))
    joint.set("type", "fixed")
    for child in [c for c in joint if c.tag in ("axis", "limit", "mimic", "dynamics",
                                                 "safety_controller", "calibration")]:
        joint.remove(child)


#: Pinocchio's planar joint (``JointModelPlanar``): the one multi-dof joint supported, as
#: the root joint of a mobile base.
_PLANAR = "JointModelPlanar"

#: Names given to the MuJoCo joints of a planar root joint: suffixes to its Pinocchio name.
PLANAR_SUFFIXES = (":x", ":y", ":heading")


def build_mujoco_model(
    model: pin.Model, urdf_text: str, frames: Iterable[str],
    locked_joints: Mapping[str, Sequence[float]] | None = None,
) -> tuple[mujoco.MjModel, JointMap]:
    """Compile a MuJoCo model of the URDF with a site at each Pinocchio frame in ``frames``.

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

    Raises ``ValueError`` when the two models' joints differ (names, or a joint that is
    neither a 1-dof revolute/prismatic joint in both nor a planar root joint).
    """
    spec = mujoco.MjSpec.from_string(_kinematic_urdf(urdf_text, locked_joints or {}))
    # massless links are fine for kinematics: bound mass/inertia so that they compile
    spec.compiler.boundmass = 1e-6
    spec.compiler.boundinertia = 1e-9
    bodies = {}
    for j in range(1, model.njoints):
        name = model.names[j]
        if _is_planar_root(model, j):
            bodies[j] = _add_planar_base(spec, model, name)
            continue
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
    mj_model = spec.compile()
    return mj_model, _joint_map(model, mj_model)


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


def _joint_map(model: pin.Model, mj_model: mujoco.MjModel) -> JointMap:
    scalar = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
    mj_names = [mj_model.joint(i).name for i in range(mj_model.njnt)]
    pin_names = [n for j in range(1, model.njoints) for n in _mujoco_names(model, j)]
    if sorted(mj_names) != sorted(pin_names):
        raise ValueError(
            f"joints differ between Pinocchio {pin_names} and MuJoCo {mj_names}")
    names, pin_q, pin_v, mj_q, mj_v = [], [], [], [], []
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
        if model.nqs[j] != 1 or model.nvs[j] != 1 or int(mj_model.jnt_type[jid]) not in scalar:
            raise ValueError(
                f"joint {name!r}: only 1-dof revolute/prismatic joints and a planar root "
                f"joint are supported (Pinocchio nq={model.nqs[j]}, nv={model.nvs[j]}, "
                f"MuJoCo type {mujoco.mjtJoint(int(mj_model.jnt_type[jid])).name})")
        names.append(name)
        pin_q.append(model.idx_qs[j])
        pin_v.append(model.idx_vs[j])
        mj_q.append(mj_model.jnt_qposadr[jid])
        mj_v.append(mj_model.jnt_dofadr[jid])
    heading_coordinates = 0 if base is None else 1  # (cos, sin) in Pinocchio, th in MuJoCo
    if mj_model.nq != model.nq - heading_coordinates or mj_model.nv != model.nv:
        raise ValueError(f"MuJoCo nq/nv = {mj_model.nq}/{mj_model.nv}, "
                         f"Pinocchio {model.nq}/{model.nv}")
    pin_q, pin_v, mj_q, mj_v = (np.array(i, dtype=int) for i in (pin_q, pin_v, mj_q, mj_v))
    identity = bool(base is None
                    and np.array_equal(pin_q, mj_q) and np.array_equal(pin_v, mj_v)
                    and np.array_equal(pin_q, np.arange(model.nq))
                    and np.array_equal(pin_v, np.arange(model.nv)))
    return JointMap(tuple(names), pin_q, pin_v, mj_q, mj_v, identity, base)


# ----------------------------------------------------------------------------- rows


class PinocchioRows:
    """Our constraint rows, evaluated with Pinocchio at a mink configuration.

    One Pinocchio kinematics pass per configuration, shared by all constraint tasks and
    barrier limits; each constraint's ``(A, b)`` (Pinocchio column order, ``A qd = b``,
    :meth:`constraints.Constraint.rows`) is then computed once and cached until the
    configuration changes.
    """

    def __init__(self, model: pin.Model, data: pin.Data, joints: JointMap,
                 mujoco_nq: int) -> None:
        self.model = model
        self.data = data
        self.joints = joints
        self._q_mj = np.full(mujoco_nq, np.nan)
        self._q_pin = np.empty(model.nq)
        self.version = 0

    def mark_current(self, q_mj: np.ndarray) -> None:
        """Declare ``self.data`` up to date (joint Jacobians, frames) at ``q_mj``."""
        self._q_mj[:] = q_mj
        self.version += 1

    def ensure(self, configuration: mink.Configuration) -> None:
        """Bring ``self.data`` to ``configuration.q`` if it is not there already."""
        q_mj = configuration.q
        if (q_mj == self._q_mj).all():
            return
        self.joints.q_to_pinocchio(q_mj, out=self._q_pin)
        pin.computeJointJacobians(self.model, self.data, self._q_pin)
        pin.updateFramePlacements(self.model, self.data)
        self.mark_current(q_mj)


class _RowsCache:
    """``(A_pin, A_mj, b)`` of one constraint, recomputed when the kinematics change."""

    def __init__(self, constraint: Constraint, frame_id: int, rows: PinocchioRows) -> None:
        self.constraint = constraint
        self.frame_id = frame_id
        self.rows = rows
        self._version = -1
        self.A_pin = self.A_mj = self.b = np.zeros(0)

    def at(self, configuration: mink.Configuration) -> "_RowsCache":
        rows = self.rows
        rows.ensure(configuration)
        if self._version != rows.version:
            self.A_pin, self.b = self.constraint.rows(rows.model, rows.data, self.frame_id)
            self.A_mj = rows.joints.columns_to_mujoco(self.A_pin, configuration.q)
            self._version = rows.version
        return self


class ConstraintTask(mink.Task):
    """An equality constraint ``A qd = b`` as a mink task, to pass in ``constraints=``.

    mink holds a task in ``constraints=`` as the hard row ``J dq = -gain e`` on the
    displacement ``dq = v dt``. With::

        J = A,   e = -b dt,   gain = 1

    that row is ``A v dt = b dt``, i.e. exactly ``A v = b`` in rad/s: the same rows, drift
    feedback ``-K e_c`` and feed-forward as the CJM and QP controllers. (``e`` is the
    *displacement* the row asks for in one step, with the sign mink expects; as a soft
    task it would cost ``|A dq - b dt|^2``.)
    """

    def __init__(self, cache: _RowsCache, dt: float) -> None:
        super().__init__(cost=np.ones(cache.constraint.dim), gain=1.0, lm_damping=0.0)
        self.cache = cache
        self.dt = float(dt)
        #: the right-hand side held instead of ``b`` (the least-residual stage), or None
        self.held_rhs: np.ndarray | None = None

    @property
    def constraint(self) -> Constraint:
        return self.cache.constraint

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        """``e = -b dt`` (k,), so that ``J dq = -e`` reads ``A v = b`` (``held_rhs``
        instead of ``b`` when set)."""
        rows = self.cache.at(configuration)
        return -self.dt * (rows.b if self.held_rhs is None else self.held_rhs)

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        """``J = A`` (k x nv), columns in MuJoCo dof order."""
        return self.cache.at(configuration).A_mj


class BarrierLimit(mink.Limit):
    """A barrier ``A qd >= b`` (``n . v_c >= -K d + n . v_plane``) as a mink limit.

    mink limits are ``G dq <= h`` on ``dq = v dt``, so the row is
    ``G = -A``, ``h = -b dt`` (``A v >= b``, scaled by ``dt > 0``): the QP controller's
    ``G qd <= h`` row, in mink's units.
    """

    def __init__(self, cache: _RowsCache) -> None:
        self.cache = cache
        #: the bound held instead of ``b`` (the least-residual stage), or None
        self.held_rhs: np.ndarray | None = None

    @property
    def constraint(self) -> Constraint:
        return self.cache.constraint

    def compute_qp_inequalities(
        self, configuration: mink.Configuration, dt: float
    ) -> LimitRows:
        """``G dq <= h`` with ``G = -A`` (MuJoCo columns) and ``h = -b dt``."""
        rows = self.cache.at(configuration)
        return LimitRows(G=-rows.A_mj, h=-dt * (rows.b if self.held_rhs is None
                                                else self.held_rhs))


class PostureTask(mink.Task):
    """mink's posture task with the CJM's posture velocity, in MuJoCo coordinates.

    ``mink.PostureTask`` has ``e = q (-) q_posture`` (``mj_differentiatePos``) and
    ``J = I``, so ``J dq = -gain e`` asks for ``dq = gain (q_posture (-) q)``. This one
    takes the difference with Pinocchio, ``e = -map(posture_difference(q, q_posture))``
    (``JointMap.v_to_mujoco``, ``Controller.posture_difference``: ``pin.difference``
    without a mobile base's entries), as the CJM's ``qd_posture`` does. For 1-dof joints the
    two are the same numbers; on a planar base MuJoCo's difference is the world-frame
    ``(dx, dy, dth)`` while Pinocchio's is the SE(2) logarithm in the base frame, and
    only the latter makes mink's posture the CJM's (docs/design.md section 11).
    """

    def __init__(self, model: pin.Model, joints: JointMap, posture: np.ndarray,
                 cost: float, gain: float,
                 difference: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> None:
        super().__init__(cost=np.full(model.nv, cost), gain=gain, lm_damping=0.0)
        self.joints = joints
        self.posture = posture
        self.difference = difference  # the controller's posture_difference
        self._q_pin = np.empty(model.nq)
        self._identity = np.eye(model.nv)

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        """``e = -(q_posture (-) q)`` (nv,), MuJoCo velocity coordinates."""
        q_mj = configuration.q
        q_pin = self.joints.q_to_pinocchio(q_mj, out=self._q_pin)
        return -self.joints.v_to_mujoco(self.difference(q_pin, self.posture), q_mj)

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        """``J = I`` (nv x nv)."""
        return self._identity


class DampingTask(mink.Task):
    """The CJM's damping as a mink task: ``|D dq|^2`` (:mod:`controllers.task_damping`),
    ``D`` in MuJoCo columns, padded with zero rows to the task's size; error 0."""

    def __init__(self, size: int, nv: int) -> None:
        super().__init__(cost=np.ones(size), gain=1.0, lm_damping=0.0)
        self.rows = np.zeros((size, nv))
        self._error = np.zeros(size)

    def set_rows(self, rows: np.ndarray) -> None:
        self.rows[:] = 0.0
        self.rows[:rows.shape[0]] = rows

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        return self._error

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        return self.rows


# ----------------------------------------------------------------------------- controller

LimitSpec = mink.Limit | Callable[[mujoco.MjModel], mink.Limit]


class MinkController(Controller):
    """The constrained teleoperation step solved by mink's ``solve_ik``.

    Per step, with ``T_e`` the EE pose and ``V`` the desired EE body twist (several EEs:
    one FrameTask each, ``V_i`` the ``i``-th 6 entries of the stacked twist, and the
    first term summed over them; docs/design.md section 11)::

        target  = T_e exp6(V dt)                    FrameTask on the EE site (cost 1, 1)
        min_dq  |Jlog(T_t^-1 T_e) (J_e dq - V dt)|^2 + c^2 |dq - qd_posture dt|^2 + damping |dq|^2
        s.t.    A dq = b dt                         ConstraintTask per equality (hard)
                -A_b dq <= -b_b dt                  BarrierLimit per barrier
                lower dt <= dq <= upper dt          JointBoxLimit (JointBounds.box(q))
        qd = dq / dt                                (solve_ik's return value)

    **Why this tracks V exactly.** mink's frame error is ``e = log(T_e^-1 T_t) = V dt``
    (for ``|V dt|`` below pi) and its Jacobian ``J = -Jlog(exp(-V dt)) J_e``, so the
    task row ``J dq = -e`` reads ``Jr^-1(-V dt) J_e dq = V dt``. Since
    ``Jr^-1(-x) x = x`` on SE(3) (``ad_x x = 0``), its solution is ``J_e dq = V dt``,
    i.e. ``J_e qd = V``: whenever the constrained task is feasible (6 + k = n, the
    built-in robots with a hole), mink's ``qd`` is the CJM's. When it is not (e.g. a
    barrier is active) mink minimises ``|J_e qd - V|`` in the metric
    ``W = Jr^-1(-V dt) = I + O(|V dt|)`` instead of the QP controller's identity:
    the two least-squares answers then differ by ``O(|V dt|)`` relative.

    **Accuracy floor.** mink 1.3.0 evaluates ``Jlog`` (``mink/lie/se3.py::_getQ``) with
    ``(1 - t^2/2 - cos t) / t^4`` and a similar quintic term in closed form once ``t^2``
    exceeds machine epsilon; at ``t = |w| dt ~ 1e-5`` rad the cancellation leaves
    ``Jlog`` wrong by ~1e-7, so ``J_e qd`` misses ``V`` by ~1e-9 m/s and ``qd`` differs
    from the CJM's by up to a few 1e-8 rad/s (on the built-in robots, every backend).

    **Posture.** A :class:`PostureTask` towards ``posture`` with gain
    ``posture_gain * dt`` (mink's gain is per step) asks for the CJM's and the QP
    controller's posture velocity ``qd_posture = posture_gain * pin.difference(q,
    posture)``. mink sums its tasks, so the posture's cost ``c`` trades the twist for the
    posture by about ``c^2 / sigma^2`` (``sigma`` the task's singular values): the QP
    controller's weighted formulation with ``mu s = c^2``, never its lexicographic one.
    The default cost is about as small as mink's solve still resolves the posture with:
    docs/design.md section 10 gives the deviation from the CJM that remains.

    **Equalities.** Every equality (``Hole``, ``Plane``, ``PointLock``) is a
    :class:`ConstraintTask` in ``solve_ik(..., constraints=...)`` and barriers are
    :class:`BarrierLimit` rows; both evaluate the constraints' own ``rows`` with
    Pinocchio at mink's configuration (joints mapped by name). After the solve the rows
    are checked: ``info.equality_residual = max |A qd - b|``, and a residual above
    ``equality_tolerance`` (infeasible equalities that a backend answered in the least
    squares sense) is a failure like a ``NoSolutionFound``: a flagged zero command.

    Parameters
    ----------
    robot : a ``teleop.Robot`` (``urdf_path``, ``model``, ``ee_frames``, ...). The MuJoCo
        model is compiled from the same URDF (geometry dropped), with a site at every
        Pinocchio link frame (``site_name(link)``, the constraint links among them) and
        at every EE frame. Joints must be 1-dof revolute/prismatic, matched by name, on
        a fixed base or on a planar root joint (:func:`build_mujoco_model`).
    constraints, strict : see :class:`controllers.base.Controller`.
    solver : any qpsolvers backend mink accepts: ``"daqp"`` (default), ``"proxqp"``,
        ``"osqp"``, ...
    dt : control period (s): mink's integration step.
    damping : mink's Levenberg-Marquardt damping (on ``dq``; acts as ``mu`` on ``qd``).
        Default: 0 with a posture task, :data:`DEFAULT_DAMPING` without.
    posture : configuration the redundancy is spent on (default ``robot.q_home``), as the
        CJM's.
    posture_gain : gain (1/s) of the posture velocity, as the CJM's (at most ``1 / dt``:
        mink's per-step gain is ``posture_gain * dt`` and must not exceed 1).
    posture_cost : the posture task's cost relative to the task's scale: mink's cost is
        ``c = posture_cost * sqrt(s)``, ``s = |W^1/2 J_e|_F^2 / m`` (``J_e`` stacked, ``m = 6`` rows
        per EE: the mean squared singular value, as the QP controller's ``s``),
        set every step (0: no posture task). With proxqp, its ``rho`` follows as
        ``PROXQP_RHO c^2`` (``controllers.qp``): proxqp's own 1e-6 against the curvature
        ``c^2`` failed every step of the 64-DoF chains with binding limits.
    limits : ``None`` for the default, the controller's joint box
        (:class:`controllers.mink_joint_box.JointBoxLimit`: velocity limits, and position
        limits through ``dt`` with ``limit_gain``, on Pinocchio's velocity, a planar base's
        in its own frame; docs/design.md 10.7),
        else a sequence of ``mink.Limit`` instances or factories ``f(mj_model) -> Limit``
        (``mink.ConfigurationLimit`` itself is one); ``()`` for none. Barrier limits
        are always added.
    limit_gain : ``g`` of the joint box (:class:`controllers.joint_limits.JointBounds`).
    equality_tolerance : largest ``|A qd - b|`` (m/s) accepted from the backend.
    solver_settings : backend keyword arguments, passed as they are (they override the
        defaults built from ``VELOCITY_TOLERANCES`` and ``FIXED_SETTINGS``).
    twist_weight : the diagonal ``W`` of the CJM's and the QP's weighted task: each frame
        task's position and orientation costs are ``W^1/2`` of its EE's entries.
    time_budget, singular_threshold, max_damping : the step's deadline and the CJM's
        damping policy, as :class:`controllers.QPController`'s (docs/design.md 10.6, 10.7).
    """

    def __init__(
        self,
        robot,
        constraints: Iterable[Constraint] = (),
        solver: str = "daqp",
        dt: float = 1e-3,
        damping: float | None = None,
        posture: np.ndarray | None = None,
        posture_gain: float = 1.0,
        posture_cost: float = DEFAULT_POSTURE_COST,
        limits: Sequence[LimitSpec] | None = None,
        limit_gain: float = DEFAULT_LIMIT_GAIN,
        equality_tolerance: float = 1e-6,
        solver_settings: dict | None = None,
        twist_weight=None,
        time_budget: TimeBudget = "periods",
        singular_threshold: float = 0.01,
        max_damping: float = 0.05,
        strict: bool = False,
    ) -> None:
        super().__init__(robot, dt=dt, limit_gain=limit_gain, strict=strict)
        self.budget = StepBudget(time_budget, self.dt)
        self.policy = DampingPolicy(0.0, as_number(singular_threshold, "singular_threshold", 0.0),
                                    as_number(max_damping, "max_damping", 0.0))
        self.twist_weight = as_twist_weight(twist_weight, self.task_size)
        self._twist_scale = np.sqrt(self.twist_weight)  # W^1/2: each frame task's costs
        self._twist_rows = self._twist_scale[:, None]  # W^1/2, to scale the rows of J_e
        self._unit_weight = bool(np.all(self.twist_weight == 1.0))
        if solver not in qpsolvers.available_solvers:
            raise ValueError(
                f"QP solver {solver!r} is not available to mink; installed: "
                f"{qpsolvers.available_solvers}")
        self.posture_gain = as_number(posture_gain, "posture_gain", 0.0, maximum=1.0 / self.dt)
        self.posture_cost = as_number(posture_cost, "posture_cost", 0.0)
        if damping is None:
            damping = 0.0 if self.posture_cost > 0.0 else DEFAULT_DAMPING
        self.damping = as_number(damping, "damping", 0.0)
        self.equality_tolerance = as_number(equality_tolerance, "equality_tolerance", positive=True)
        self.solver = solver
        self.settings = {key: value * self.dt
                         for key, value in VELOCITY_TOLERANCES.get(solver, {}).items()}
        self.settings.update(FIXED_SETTINGS.get(solver, {}))
        self.settings.update(MINK_ITERATION_CAPS.get(solver, {}))
        self.settings.update(solver_settings or {})
        #: iteration caps the user set: the least-residual solve takes them too
        self._user_caps = {k: v for k, v in (solver_settings or {}).items()
                           if k in ITERATION_CAPS.get(solver, {})}
        #: proxqp's rho follows the posture cost, unless the user set it
        self._proxqp_rho_tuned = (solver == "proxqp" and self.posture_cost > 0.0
                                  and "rho" not in (solver_settings or {}))
        #: proxqp runs on the QP controller's proxsuite objects, which cap its inner
        #: iterations too (unless a setting is one they cannot apply: then qpsolvers)
        self._proxqp = self._least_residual_proxqp = None
        if solver == "proxqp" and ProxQPSolver.accepts(self.settings):
            self._proxqp = ProxQPSolver(self.settings, frozenset(
                {"rho"} if self._proxqp_rho_tuned else ()))
            self._least_residual_proxqp = ProxQPSolver(
                {**SOLVER_SETTINGS["proxqp"], **ITERATION_CAPS["proxqp"], **self._user_caps},
                frozenset({"eps_abs", "rho"}))
        self._posture_curvature = 1.0  # c^2, the curvature the posture task gives mink's QP

        # The MuJoCo side, built once, before the constraints that use it.
        model: pin.Model = robot.model
        ee_frames = [model.frames[frame_id].name for frame_id in self.ee_frame_ids]
        frames = [f.name for f in model.frames if f.type == pin.FrameType.BODY]
        frames.extend(ee_frames)
        self.mj_model, self.joints = build_mujoco_model(
            model, robot.urdf_path.read_text(), frames, getattr(robot, "locked_joints", None))
        self.site_names = {name: site_name(name) for name in frames}
        self.ee_site = site_name(ee_frames[0])
        self.configuration = mink.Configuration(self.mj_model)
        #: one frame task per end effector, in ``robot.ee_frames`` order
        self.ee_tasks = [mink.FrameTask(site_name(name), "site",
                                        position_cost=self._twist_scale[6 * i:6 * i + 3],
                                        orientation_cost=self._twist_scale[6 * i + 3:6 * i + 6],
                                        gain=1.0, lm_damping=0.0)
                         for i, name in enumerate(ee_frames)]
        self._ee_site_ids = [self.mj_model.site(site_name(name)).id for name in ee_frames]
        self._q_mj = np.empty(self.mj_model.nq)
        #: the default limit, the controller's joint box (None with ``limits`` given)
        self._joint_box = (JointBoxLimit(self.joint_bounds, self.joints, model.nq)
                           if limits is None else None)
        self._base_limits = self._make_limits(limits)
        if posture is None:
            posture = robot.q_home
        self.posture = as_vector(posture, model.nq, "posture")
        self.posture_task = PostureTask(model, self.joints, self.posture, cost=self.posture_cost,
                                        gain=self.posture_gain * self.dt,
                                        difference=self.posture_difference)
        self._tasks = [*self.ee_tasks, self.posture_task] if self.posture_cost else self.ee_tasks
        self.damping_task = DampingTask(self.task_size, self.mj_model.nv)
        #: the task rows the damping sees: those of non-zero weight, as the CJM's
        self._weighted_rows = np.flatnonzero(self.twist_weight > 0.0)
        self._equality_caches: list[_RowsCache] = []
        self.constraint_tasks: list[ConstraintTask] = []
        self.barrier_limits: list[BarrierLimit] = []
        self._limits: list[mink.Limit] = list(self._base_limits)
        self.set_constraints(constraints)

    def _make_limits(self, limits: Sequence[LimitSpec] | None) -> list[mink.Limit]:
        if limits is None:
            return [self._joint_box]
        made = []
        for limit in limits:
            made.append(limit if isinstance(limit, mink.Limit) else limit(self.mj_model))
            if not isinstance(made[-1], mink.Limit):
                raise TypeError(f"limits: expected mink.Limit or a factory of one, got {limit!r}")
        return made

    @property
    def ee_task(self) -> mink.FrameTask:
        """The first end effector's frame task (the only one of a single-EE robot)."""
        return self.ee_tasks[0]

    def _prepare(self) -> None:
        rows = PinocchioRows(self.model, self.data, self.joints, self.mj_model.nq)
        self._rows = rows
        caches = [_RowsCache(c, f, rows) for c, f in zip(self.constraints, self.constraint_frames)]
        self._equality_caches = [c for c in caches if c.constraint.is_equality]
        self.constraint_tasks = [ConstraintTask(c, self.dt) for c in self._equality_caches]
        self.barrier_limits = [BarrierLimit(c) for c in caches if not c.constraint.is_equality]
        self._limits = [*self._base_limits, *self.barrier_limits]

    # -- the step ----------------------------------------------------------------------

    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        configuration = self.configuration
        q_mj = self.joints.q_to_mujoco(kinematics.q, out=self._q_mj)
        configuration.update(q_mj)
        self._rows.mark_current(q_mj)  # the base class ran Pinocchio at this q already
        data = configuration.data
        dt = self.dt
        for index, (task, site_id) in enumerate(zip(self.ee_tasks, self._ee_site_ids)):
            ee = pin.SE3(data.site_xmat[site_id].reshape(3, 3), data.site_xpos[site_id])
            xyz_quat = pin.SE3ToXYZQUAT(ee * pin.exp6(twist[6 * index:6 * index + 6] * dt))
            # (the attribute set_target would set, without its defensive copy)
            task.transform_target_to_world = mink.SE3(wxyz_xyz=xyz_quat[_WXYZ_XYZ])
        self.info.method = f"mink:{self.solver}"
        if self.posture_cost > 0.0:  # c = posture_cost * sqrt(s), s the task's scale
            cost = self.posture_cost * math.sqrt(
                float(np.vdot(self.twist_weight, np.square(kinematics.ee_jacobian).sum(axis=1)))
                / self.task_size)
            self.posture_task.cost[:] = cost  # (set_cost, without its checks)
            self._posture_curvature = cost**2
            if self._proxqp_rho_tuned and self._proxqp is None:
                self.settings["rho"] = PROXQP_RHO * cost**2
        self.budget.start()
        A, b = self._equality_rows()
        damping = task_damping(A, (self._twist_rows * kinematics.ee_jacobian)[self._weighted_rows],
                               self.policy)
        self.info.sigma_min, self.info.damping = damping.sigma_min, damping.damping
        tasks = self._tasks
        if damping.rows.shape[0]:
            self.damping_task.set_rows(self.joints.columns_to_mujoco(damping.rows, q_mj))
            tasks = [*tasks, self.damping_task]
        try:
            qd = self._solve_rows(tasks, q_mj)
        except SolverError as error:  # infeasible rows, or a budget spent
            if not (self._equality_caches or self.barrier_limits):
                raise
            try:
                held = self._least_residual(A, b, kinematics.q)
            except SolverError as second:
                raise error from second
            if held.residual <= EQUALITY_TOLERANCE:
                raise  # the rows fit the limits: the failure was something else
            self.info.report(StepStatus.CONSTRAINT_DEGRADED, held_note(held.residual))
            self._hold(held)
            try:
                qd = self._solve_rows(tasks, q_mj)
            except BudgetExceeded:
                raise
            except SolverError as task_error:  # (proxqp: a false infeasibility, in dq units)
                qd = held.qd
                self.info.report(StepStatus.LEAST_SQUARES, f"mink under the held rows failed "
                                 f"({task_error}): the least-residual command")
            finally:
                self._hold(None)
        if A is not None:
            self.info.equality_residual = float(np.max(np.abs(A @ qd - b)))
        if self.barrier_limits:
            active = []
            for index, limit in zip(
                    (i for i, c in enumerate(self.constraints) if not c.is_equality),
                    self.barrier_limits):
                rows = limit.cache.at(configuration)
                if np.any(rows.A_pin @ qd - rows.b < 1e-9):
                    active.append(index)
            self.info.active_barriers = tuple(active)
        self._report_twist_error(kinematics.ee_jacobian, qd, twist,
                                 None if self._unit_weight else self._twist_scale)
        return qd

    def _solve_rows(self, tasks: list[mink.Task], q_mj: np.ndarray) -> np.ndarray:
        """mink's ``qd`` (Pinocchio order) under the rows as the constraint tasks hold them
        (``b``, or the least residual's), which it must meet to ``equality_tolerance``."""
        v_mj = self._solve_ik(tasks)
        if not np.all(np.isfinite(v_mj)):
            raise SolverError(f"mink.solve_ik with solver {self.solver!r} returned a "
                              "non-finite velocity")
        qd = self.joints.v_to_pinocchio(v_mj, q_mj)
        if self._equality_caches:
            residual = max(float(np.max(np.abs(
                task.cache.A_pin @ qd - (task.cache.b if task.held_rhs is None else task.held_rhs))))
                for task in self.constraint_tasks)
            if not residual <= self.equality_tolerance:  # daqp's eq_reduction: least squares
                raise SolverError(
                    f"mink.solve_ik with solver {self.solver!r} returned a velocity that "
                    f"breaks the equality rows by {residual:.3g} m/s (tolerance "
                    f"{self.equality_tolerance:g}): infeasible constraints or an "
                    "inaccurate solve")
        return qd

    def _solve_ik(self, tasks: list[mink.Task]) -> np.ndarray:
        """``mink.build_ik`` solved within the step's budget (``solve_ik``'s two lines, so
        that a budget spent is told from an infeasible problem). proxqp: by
        :meth:`_solve_proxqp`."""
        settings = self.settings
        self.budget.remaining(self.solver)
        try:
            problem = mink.build_ik(self.configuration, tasks, self.dt, self.damping,
                                    self._limits, self.constraint_tasks)
            if self._joint_box is not None:  # its 1-dof joints bound the variable
                lb, ub = self._joint_box.displacement_bounds(self.configuration, self.dt)
                problem.lb = np.maximum(lb, -INFINITE_BOUND)
                problem.ub = np.minimum(ub, INFINITE_BOUND)
            if self._proxqp is not None:
                return self._solve_proxqp(problem) / self.dt
            solution = qpsolvers.solve_problem(problem, solver=self.solver, **settings)
        except SolverError:
            raise

        except Exception as error:  # backend errors
            raise SolverError(f"mink with solver {self.solver!r} raised "
                              f"{type(error).__name__}: {error}") from error
        if not solution.found or solution.x is None:
            status = str(getattr(solution.extras.get("info"), "status", ""))
            if ("time limit" in status or "maximum iterations" in status
                    or "MAX_ITER" in status):
                raise self.budget.exceeded(f"mink:{self.solver}", status)
            raise SolverError(f"mink with solver {self.solver!r} found no solution "
                              f"({status or 'infeasible, or out of iterations'})")
        return solution.x / self.dt

    def _solve_proxqp(self, problem: qpsolvers.Problem) -> np.ndarray:
        """mink's QP ``min 1/2 dq'P dq + q'dq  s.t.  G dq <= h,  A dq = b`` by a fresh
        capped proxsuite solve (as ``qpsolvers``' proxqp path: no state carried between
        steps), ``rho`` from the posture's curvature ``c^2`` as before."""
        P, q, G, h, A, b, lb, ub = problem.unpack()
        self._proxqp.reset()
        try:
            return self._proxqp.solve(QuadraticProgram(
                np.asarray(P, dtype=float), q, A, b, G,
                None if G is None else np.full(G.shape[0], -INFINITE_BOUND), h, lb, ub,
                curvature=self._posture_curvature), self.budget).x
        except SolverError as error:  # the same type, naming mink
            raise type(error)(f"mink:{error}") from error

    def _equality_rows(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """The equality rows ``A qd = b`` at the current configuration (Pinocchio order)."""
        if not self._equality_caches:
            return None, None
        caches = [cache.at(self.configuration) for cache in self._equality_caches]
        return np.vstack([c.A_pin for c in caches]), np.concatenate([c.b for c in caches])

    def _least_residual(self, A: np.ndarray | None, b: np.ndarray | None,
                        q: np.ndarray) -> HeldRows:
        """The rows as close to ``b`` as the box and the barriers allow
        (:mod:`controllers.least_residual`), solved with this controller's backend."""
        lower, upper = self.joint_bounds.box(q)
        lower = np.where(np.isfinite(lower), lower, -INFINITE_BOUND)
        upper = np.where(np.isfinite(upper), upper, INFINITE_BOUND)
        G = h = None
        if self.barrier_limits:
            caches = [limit.cache.at(self.configuration) for limit in self.barrier_limits]
            G = -np.vstack([c.A_pin for c in caches])
            h = -np.concatenate([c.b for c in caches])
        problem = least_residual_problem(A, b, G, h, lower, upper, INFINITE_BOUND)
        if self._least_residual_proxqp is not None:
            self._least_residual_proxqp.reset()
            solution = self._least_residual_proxqp.solve(QuadraticProgram(
                problem.hessian, problem.gradient, rows=problem.rows,
                rows_lower=problem.rows_lower, rows_upper=problem.rows_upper,
                lower=problem.lower, upper=problem.upper, curvature=problem.curvature,
                semidefinite=problem.semidefinite), self.budget)
            return held_rows(solution.x, A, b, G, h, lower, upper)
        settings = {**SOLVER_SETTINGS.get(self.solver, {}), **ITERATION_CAPS.get(self.solver, {}),
                    **self._user_caps}
        self.budget.remaining(self.solver)
        if self.solver == "daqp" and problem.semidefinite:  # as the QP controller's
            settings.update(eps_prox=DAQP_PROXIMAL_WEIGHT, eta_prox=max(
                TASK_ACCURACY * problem.curvature, DAQP_PROXIMAL_FLOOR))
        qp = qpsolvers.Problem(problem.hessian, problem.gradient, problem.rows,
                               problem.rows_upper, lb=problem.lower, ub=problem.upper)
        try:
            solution = qpsolvers.solve_problem(qp, solver=self.solver, **settings)
        except Exception as error:  # backends raise their own types
            raise SolverError(f"{self.solver} raised {type(error).__name__}: {error}") from error
        if not solution.found or solution.x is None:
            raise SolverError(f"{self.solver} found no least-residual solution")
        return held_rows(solution.x, A, b, G, h, lower, upper)

    def _hold(self, held: HeldRows | None) -> None:
        """Make the constraint tasks and barrier limits hold ``held``'s rows (None: ``b``)."""
        if held is None:
            for item in (*self.constraint_tasks, *self.barrier_limits):
                item.held_rhs = None
            return
        for task in self.constraint_tasks:
            task.held_rhs = task.cache.A_pin @ held.qd
        for limit in self.barrier_limits:
            limit.held_rhs = np.minimum(limit.cache.b, limit.cache.A_pin @ held.qd)

    def site_pose(self, frame: str) -> pin.SE3:
        """World pose of the MuJoCo site at Pinocchio frame ``frame`` (last ``solve``'s q)."""
        sid = self.mj_model.site(site_name(frame)).id
        data = self.configuration.data
        return pin.SE3(data.site_xmat[sid].reshape(3, 3).copy(), data.site_xpos[sid].copy())
