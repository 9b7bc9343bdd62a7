"""A robot with a body: MuJoCo rigid-body dynamics under the controllers (docs/design.md
section 17).

The loop's command is a joint velocity, as on an industrial robot's velocity interface:
each joint's drive integrates it into a position reference and tracks it with a stiff
servo with velocity feed-forward and gravity compensation of the modelled robot,

    q_ref <- q_ref + v_cmd h,    tau = kp (q_ref - q) + kd (v_cmd - qd) + g(q),

clipped to the joint's effort limit, at ``h = dt / substeps`` (2 kHz or faster under a
1 kHz loop). The command reaches the drives after the imperfections' latency, through the
interface's check of the robot's acceleration and jerk limits
(:mod:`teleop.plants.interface`), then the joint lag. Every hole puts a port into the scene: the
abdominal wall pushes on the
instrument with the hole's own spring-damper (:meth:`constraints.Hole.wall_force`),
applied at the instrument's point nearest the port centre. With a collision avoidance,
the robot's collision geometry and the obstacles are in the scene, in contact in the
avoidance's pairs (:mod:`teleop.plants.contact_geometry`), and each period counts the
contacts (docs/design.md section 18.6).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import mujoco
import numpy as np
import pinocchio as pin

from constraints import Constraint
from controllers.mujoco_model import joint_map, mujoco_spec, site_name

from constraints.collision import CollisionAvoidance

from .armature import urdf_armatures
from .contact_geometry import add_contact_geometry
from .imperfect import Imperfections, ImperfectPlant
from .interface import CommandInterface, InterfaceFault
from .settings import PlantSettings

#: A payload's inertia: a 5 cm solid sphere's per kilogram (kg m^2 / kg).
_PAYLOAD_INERTIA_PER_KG = 0.4 * 0.05 ** 2


@dataclass
class PlantMeasures:
    """What the plant measured over one control period (docs/design.md section 17.3).

    Attributes
    ----------
    port_forces : (holes, 3) the wall's force on each instrument, world frame (N), at the
        period's last physics step, in the order of the holes among the constraints.
    port_spring_forces : (holes, 3) its spring part ``-k (P - c)`` (N); the rest,
        ``port_forces - port_spring_forces``, is the damper's (docs/design.md 17.2).
    port_displacements : (holes,) the tissue's lateral displacement at each port (m).
    torque_ratio : max over joints of |drive torque| / effort limit (gravity compensation
        included) at the period's last physics step.
    saturated : some drive was held at its effort limit at that step.
    contacts : the robot's contacts at that step in the collision avoidance's pairs
        (robot-robot, robot-obstacle); 0 without collision avoidance.
    contact_depth : the deepest of them (m), 0 without contact.
    interface_fault : the command the interface refused (``strict``) or counted
        (``count``) this period, None: none (docs/design.md 17.1, "The interface").
    interface_stopped : the interface has stopped the robot (``strict``, from the first
        fault on).
    """

    #: measures of a simulated body (the ROS 2 plant's are not: no port force, no torque)
    physical: ClassVar[bool] = True

    port_forces: np.ndarray
    port_displacements: np.ndarray
    torque_ratio: float
    saturated: bool
    port_spring_forces: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    contacts: int = 0
    contact_depth: float = 0.0
    interface_fault: InterfaceFault | None = None
    interface_stopped: bool = False

    @property
    def port_force(self) -> float:
        """The largest port force's magnitude (N); 0 without a hole."""
        return float(np.max(np.linalg.norm(self.port_forces, axis=1), initial=0.0))


class MujocoPlant:
    """A :class:`teleop.loop.Plant`: the robot's URDF simulated in MuJoCo.

    Parameters
    ----------
    robot : a ``teleop.Robot`` (built-in or URDF; the mobile base's x, y and heading are
        driven by their own servos like the joints).
    dt : the control period (s).
    settings : :class:`PlantSettings` (defaults documented there).
    imperfections : encoder noise, latency and joint lag on top of the physics
        (:class:`Imperfections`): the latency delays the command before the interface,
        the lag filters the velocity the drives receive after it. A calibration error is
        refused (``ValueError``): the body is the URDF's.
    collisions : a collision avoidance on ``robot``: its geometry, obstacles and pairs go
        into the simulation (:func:`~teleop.plants.contact_geometry.add_contact_geometry`);
        None: the robot has no collision geometry (nothing touches).
    """

    def __init__(self, robot, dt: float, settings: PlantSettings | None = None,
                 imperfections: Imperfections | None = None,
                 collisions: CollisionAvoidance | None = None) -> None:
        if settings is not None and not isinstance(settings, PlantSettings):
            raise ValueError(f"settings must be PlantSettings, got {type(settings).__name__}")
        if imperfections is not None and not imperfections.calibrated:
            raise ValueError("calibration error (calibration_position_std, "
                             "calibration_rotation_std) needs the kinematic plant: the mujoco "
                             "plant builds its body from the URDF, the controllers' model")
        self.settings = settings or PlantSettings()
        self.model: pin.Model = robot.model
        self.dt = float(dt)
        self.substeps = self.settings.substeps(self.dt)
        #: the imperfect robot's noise, latency and lag (None: a perfect interface)
        self.shaping: ImperfectPlant | None = (imperfections or Imperfections()).plant(
            robot.model, dt)
        #: the velocity interface's check of the robot's acceleration and jerk limits
        self.interface = CommandInterface(self.settings.interface_limits, robot.model, dt,
                                          robot.acceleration_limit,
                                          self.settings.interface_jerk_limit)
        self.mj_model = self._compile(robot, collisions)
        self.mj_data = mujoco.MjData(self.mj_model)
        self.joints = joint_map(self.model, self.mj_model)
        self._q_pin = np.empty(self.model.nq)
        self._qpos_of_dof = self.mj_model.jnt_qposadr[self.mj_model.dof_jntid]
        self.effort_limit = self._effort_limits()
        self._site_ids = {name: self.mj_model.site(site_name(name)).id
                          for name in self._site_frames(robot)}
        self._site_bodies = self.mj_model.site_bodyid.tolist()
        self._jacobian = np.empty((3, self.mj_model.nv))
        self._no_torque = np.zeros(3)
        self.reset(robot.q_home)

    # -- the model -----------------------------------------------------------------------

    @staticmethod
    def _site_frames(robot) -> list[str]:
        """Every frame a constraint or an EE can sit on (all but the universe)."""
        return list(dict.fromkeys(frame.name for frame in robot.model.frames[1:]))

    def _compile(self, robot, collisions: CollisionAvoidance | None) -> mujoco.MjModel:
        """The URDF's bodies, the drives' rotor inertia (the URDF's where it gives one,
        :func:`~teleop.plants.armature.urdf_armatures`, else the ``armature`` setting),
        damping and friction, two actuators per degree of freedom (the servo,
        :meth:`_set_servo_gains`), the payload at each EE, the collision geometry with
        ``collisions``."""
        settings = self.settings
        urdf = robot.urdf_path.read_text()
        spec = mujoco_spec(robot.model, urdf, self._site_frames(robot), robot.locked_joints)
        armatures = urdf_armatures(urdf, str(robot.urdf_path))
        spec.option.timestep = self.dt / self.substeps
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.gravity = [0.0, 0.0, -9.81 if settings.gravity else 0.0]
        for body in spec.bodies[1:]:  # the world body first
            body.gravcomp = 1.0  # the drives know the modelled robot's weight
        effort = self._urdf_efforts(robot.model)
        for joint in spec.joints:
            joint.armature = armatures.get(joint.name, settings.armature)
            joint.damping = [settings.joint_damping + settings.viscous_friction, 0.0, 0.0]
            joint.frictionloss = settings.coulomb_friction
            joint.actgravcomp = True  # the compensation is the drive's torque, within its limit
            if np.isfinite(effort.get(joint.name, np.inf)):
                joint.actfrclimited = mujoco.mjtLimited.mjLIMITED_TRUE
                joint.actfrcrange = [-effort[joint.name], effort[joint.name]]
            # the reference: the integral of the command (an activation), bounded by the
            # joint's range; then the velocity feed-forward
            reference = spec.add_actuator(name=f"position:{joint.name}", target=joint.name,
                                          trntype=mujoco.mjtTrn.mjTRN_JOINT)
            reference.set_to_intvelocity(kp=1.0, kv=0.0,
                                         inheritrange=bool(joint.range[1] > joint.range[0]))
            feed_forward = spec.add_actuator(name=f"velocity:{joint.name}", target=joint.name,
                                             trntype=mujoco.mjtTrn.mjTRN_JOINT)
            feed_forward.set_to_velocity(kv=1.0)
        if settings.payload > 0:
            for frame in robot.ee_frames:
                site = spec.site(site_name(frame))
                payload = site.parent.add_body(name=f"payload:{frame}", pos=site.pos,
                                               mass=settings.payload)
                payload.ipos = [0.0, 0.0, 0.0]  # its mass at the EE (not MuJoCo's default)
                payload.inertia = [settings.payload * _PAYLOAD_INERTIA_PER_KG] * 3
                payload.gravcomp = 0.0  # unknown to the drives
        if collisions is not None:
            add_contact_geometry(spec, robot, collisions)
        return spec.compile()

    @staticmethod
    def _urdf_efforts(model: pin.Model) -> dict[str, float]:
        """Each 1-dof joint's effort limit from the URDF (the planar base has none)."""
        efforts = {}
        for j in range(1, model.njoints):
            if model.nvs[j] == 1:
                effort = float(model.effortLimit[model.idx_vs[j]])
                efforts[model.names[j]] = effort if effort > 0 else np.inf
        return efforts

    def _effort_limits(self) -> np.ndarray:
        """Each MuJoCo dof's effort limit (inf where the URDF gives none)."""
        model = self.mj_model
        limits = np.full(model.nv, np.inf)
        for joint in range(model.njnt):
            if model.jnt_actfrclimited[joint]:
                limits[model.jnt_dofadr[joint]] = model.jnt_actfrcrange[joint, 1]
        return limits

    def _set_servo_gains(self) -> None:
        """``kp = I w^2``, ``kd = 2 zeta I w`` with ``I`` the diagonal of the joint-space
        inertia (armature included) where the robot is now, into the two actuators of
        each degree of freedom."""
        model, data = self.mj_model, self.mj_data
        mujoco.mj_forward(model, data)
        inertia = np.empty((model.nv, model.nv))
        mujoco.mj_fullM(model, data, inertia)
        diagonal = np.diag(inertia)
        omega = 2.0 * np.pi * self.settings.servo_bandwidth
        self.kp = diagonal * omega ** 2
        self.kd = 2.0 * self.settings.servo_damping_ratio * diagonal * omega
        dofs = model.jnt_dofadr[model.actuator_trnid[:, 0]]
        position = model.actuator_dyntype == mujoco.mjtDyn.mjDYN_INTEGRATOR
        kp, kd = self.kp[dofs], self.kd[dofs]
        model.actuator_gainprm[:, 0] = np.where(position, kp, kd)
        model.actuator_biasprm[:, 1] = np.where(position, -kp, 0.0)
        model.actuator_biasprm[:, 2] = np.where(position, 0.0, -kd)
        self._actuator_dofs = dofs
        self._reference_actuators = np.flatnonzero(position)
        self._activation = model.actuator_actadr[self._reference_actuators]

    # -- the Plant protocol --------------------------------------------------------------

    def reset(self, q: np.ndarray | None = None) -> None:
        """At rest at ``q`` (Pinocchio coordinates; default: where it is), the references on
        the joints, no command in flight."""
        data = self.mj_data
        if q is not None:
            mujoco.mj_resetData(self.mj_model, data)
            self.joints.q_to_mujoco(np.asarray(q, dtype=float), data.qpos)
            self._set_servo_gains()
        data.qvel[:] = 0.0
        data.act[self._activation] = data.qpos[self._qpos_of_dof[
            self._actuator_dofs[self._reference_actuators]]]
        if self.shaping is not None:
            self.shaping.reset()
        self.interface.reset()
        self.last = PlantMeasures(np.zeros((0, 3)), np.zeros(0), 0.0, False)

    def sense(self, q: np.ndarray) -> np.ndarray:
        """The simulated configuration ``q`` with the encoder noise on top."""
        return q if self.shaping is None else self.shaping.sense(q)

    def actuate(self, qd: np.ndarray, q: np.ndarray,
                constraints: Sequence[Constraint] = ()) -> np.ndarray:
        """Run the physics for one control period under the command ``qd`` (delayed by
        the imperfections' latency, checked by the interface, filtered by the joint lag);
        the mean velocity that takes the loop's true configuration ``q`` to the simulated
        one."""
        model, data = self.mj_model, self.mj_data
        arrived = qd if self.shaping is None else self.shaping.delay(qd)
        accepted, fault = self.interface.receive(arrived)
        shaped = accepted if self.shaping is None else self.shaping.respond(accepted)
        command = self.joints.v_to_mujoco(shaped, data.qpos)
        data.ctrl[:] = command[self._actuator_dofs]
        holes = [c for c in constraints if c.has_wall]
        forces, displacements = np.zeros((len(holes), 3)), np.zeros(len(holes))
        springs = np.zeros((len(holes), 3))
        data.qfrc_applied[:] = 0.0
        if holes:  # each physics step split to apply the wall's force at its kinematics
            for _ in range(self.substeps):
                mujoco.mj_step1(model, data)
                data.qfrc_applied[:] = 0.0
                for i, hole in enumerate(holes):
                    forces[i], springs[i], displacements[i] = self._push(hole)
                mujoco.mj_step2(model, data)
        else:  # one call: the physics steps without Python between them
            mujoco.mj_step(model, data, self.substeps)
        torque = np.abs(data.qfrc_actuator) / self.effort_limit
        ratio = float(np.max(torque))
        saturated = ratio >= 1.0 - 1e-12
        depths = data.contact.dist[:data.ncon]
        self.last = PlantMeasures(forces, displacements, ratio, saturated, springs,
                                  int(data.ncon),
                                  float(max(0.0, -np.min(depths, initial=0.0))),
                                  fault, self.interface.stopped)
        self.joints.q_to_pinocchio(data.qpos, self._q_pin)
        return pin.difference(self.model, q, self._q_pin) / self.dt

    def measures(self) -> PlantMeasures:
        """The last period's :class:`PlantMeasures`."""
        return self.last

    # -- the abdominal wall ----------------------------------------------------------------

    def _push(self, hole: Constraint) -> tuple[np.ndarray, np.ndarray, float]:
        """Apply the wall's force at ``hole`` to the instrument (at the kinematics of
        ``mj_step1``); the force (N), its spring part ``-k (P - c)`` (the first term of
        :meth:`constraints.Hole.wall_force`) and the tissue's displacement (m)."""
        model, data, jacobian = self.mj_model, self.mj_data, self._jacobian
        site = self._site_ids[hole.link]
        point, axis = hole.port(data.site_xmat[site].reshape(3, 3), data.site_xpos[site])
        body = self._site_bodies[site]
        mujoco.mj_jac(model, data, jacobian, None, point, body)
        force = hole.wall_force(point, axis, jacobian @ data.qvel)
        mujoco.mj_applyFT(model, data, force, self._no_torque, point, body, data.qfrc_applied)
        spring = -hole.tissue_stiffness * (point - hole.center)
        return force, spring, math.dist(point, hole.center)
