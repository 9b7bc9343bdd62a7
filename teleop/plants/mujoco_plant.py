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
instrument with the hole's own spring-damper (:mod:`teleop.plants.walls`),
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
from constraints.validation import as_number
from controllers.mujoco_model import joint_map, mujoco_spec, site_name

from constraints.collision import CollisionAvoidance

from .armature import urdf_armatures
from .contact_geometry import add_contact_geometry
from .contact_pairs import ContactPairs
from .imperfect import Imperfections, ImperfectPlant
from .interface import CommandInterface, InterfaceFault
from .settings import PlantSettings
from .tissue import TissueSurface
from .compiled_period import CONTACTS, PENETRATION, RATIO, CompiledPeriod, compiled_period
from .compiled_wall import DISPLACEMENT, FORCE, SPRING, compiled_ports
from .profiler_clock import stop_profiler_clock
from .walls import Wall, wall_of

#: A payload's inertia: a 5 cm solid sphere's per kilogram (kg m^2 / kg).
_PAYLOAD_INERTIA_PER_KG = 0.4 * 0.05 ** 2
#: The force sensor's tool body: its name prefix and mass (kg, light: the sensor reads
#: the contact, not the tool's weight or inertia) and its sensors' name prefixes.
_TOOL, _TOOL_MASS = "tool:", 1e-4
_FORCE, _TORQUE = "force:", "torque:"


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
    tool_wrenches : (EEs, 6) the force/torque sensor at each EE's tool frame: the wrench
        the environment applies to the tool (N, N m), in the tool frame, noise and bias
        included (docs/design.md section 21.2); ``(0, 6)`` without tissue.
    contact_forces : (EEs, 3) the tissues' true force on each tool tip, world frame (N).
    contact_depths : (EEs,) each tip's deepest penetration into a tissue (m).
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
    tool_wrenches: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    contact_forces: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    contact_depths: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def port_force(self) -> float:
        """The largest port force's magnitude (N); 0 without a hole."""
        return largest_force(self.port_forces)


def largest_force(forces: np.ndarray) -> float:
    """The largest magnitude (N) of ``forces`` (n, 3), ``sqrt(max_i f_i . f_i)``; 0 for none,
    NaN if one is. The one arithmetic of a port force's magnitude: the UI's plot of the
    largest per sample (web/app/trace.py) is held to the plant's measures bit for bit."""
    if not forces.size:
        return 0.0
    return math.sqrt(float(np.max(np.einsum("ij,ij->i", forces, forces))))


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
        into the simulation (:func:`~teleop.plants.contact_geometry.add_contact_geometry`),
        the pairs following the ports among the constraints :meth:`actuate` is given
        (:class:`~teleop.plants.contact_pairs.ContactPairs`); None: the robot has no
        collision geometry (nothing touches).
    tissues : compliant surfaces every EE's tool tip can press (:class:`TissueSurface`);
        with any, each EE carries a force/torque sensor (docs/design.md section 21.2).
    sensor_noise : the force/torque sensor's white noise, standard deviation of each force
        (N) and torque (N m) component.
    sensor_bias : (6,) a constant offset on its reading (N, N m), tool frame.
    seed : the sensor noise's seed.
    compiled_walls : apply the ports' walls inside ``mj_step`` by the compiled callback
        where it is available (:mod:`teleop.plants.compiled_wall`; without tissues): a
        period is then one call, and with a perfect interface, no collision pairs and the
        same coordinates in both models the whole period is C
        (:mod:`teleop.plants.compiled_period`). False: from Python, each physics step split
        (the reference the compiled walls are tested against).
    """

    #: the plant measures the wrench at the tool (the kinematic plant does not)
    has_force_sensor: ClassVar[bool] = True

    def __init__(self, robot, dt: float, settings: PlantSettings | None = None,
                 imperfections: Imperfections | None = None,
                 collisions: CollisionAvoidance | None = None,
                 tissues: Sequence[TissueSurface] = (), sensor_noise: float = 0.0,
                 sensor_bias: Sequence[float] | None = None, seed: int = 0,
                 compiled_walls: bool = True) -> None:
        if settings is not None and not isinstance(settings, PlantSettings):
            raise ValueError(f"settings must be PlantSettings, got {type(settings).__name__}")
        if imperfections is not None and not imperfections.calibrated:
            raise ValueError("calibration error (calibration_position_std, "
                             "calibration_rotation_std) needs the kinematic plant: the mujoco "
                             "plant builds its body from the URDF, the controllers' model")
        self.settings = settings or PlantSettings()
        if not all(isinstance(tissue, TissueSurface) for tissue in tissues):
            raise ValueError("tissues must be TissueSurface objects")
        self.tissues = tuple(tissues)
        self.sensor_noise = as_number(sensor_noise, "sensor_noise", 0.0)
        bias = np.zeros(6) if sensor_bias is None else np.asarray(sensor_bias, dtype=float)
        if bias.shape != (6,) or not np.all(np.isfinite(bias)):
            raise ValueError(f"sensor_bias must be 6 finite numbers (N, N m), got "
                             f"{sensor_bias!r}")
        self.sensor_bias = bias
        self._sensor_rng = np.random.default_rng(seed)
        self.ee_frames = tuple(robot.ee_frames)
        #: (EEs, 3) an external force on each tool tip, world frame (N): :meth:`push`
        self.pushes = np.zeros((len(self.ee_frames), 3))
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
        self.contact_pairs: ContactPairs | None = None  # with collisions, set by _compile
        self.mj_model = self._compile(robot, collisions)
        self.mj_data = mujoco.MjData(self.mj_model)
        stop_profiler_clock()  # MujocoPlant reads no MjData.timer: 1.5 us of a 10 us period
        # the arrays each period reads and writes, as views of the MjData's own memory
        # (fixed for its life; each ``mj_data.<field>`` access builds a new view)
        self._qpos, self._ctrl = self.mj_data.qpos, self.mj_data.ctrl
        self._qfrc_applied = self.mj_data.qfrc_applied
        self._qfrc_actuator = self.mj_data.qfrc_actuator
        self.joints = joint_map(self.model, self.mj_model)
        self._q_pin = np.empty(self.model.nq)
        self._qpos_of_dof = self.mj_model.jnt_qposadr[self.mj_model.dof_jntid]
        self.effort_limit = self._effort_limits()
        self._effort_limit_list: list[float] = self.effort_limit.tolist()
        self._site_ids = {name: self.mj_model.site(site_name(name)).id
                          for name in self._site_frames(robot)}
        self._site_bodies = self.mj_model.site_bodyid.tolist()
        self._jacobian = np.empty((3, self.mj_model.nv))
        self._tools = [self.mj_model.body(_TOOL + frame).id for frame in self.ee_frames] \
            if self.tissues else []
        self._tool_sites = [self.mj_model.site(_TOOL + frame).id for frame in self.ee_frames] \
            if self.tissues else []
        self._sensor_rows = [(self.mj_model.sensor(_FORCE + frame).adr[0],
                              self.mj_model.sensor(_TORQUE + frame).adr[0])
                             for frame in self.ee_frames] if self.tissues else []
        self._no_torque = np.zeros(3)
        #: the walls applied inside mj_step (None: from Python, each step split)
        self._compiled_walls = compiled_ports(self.mj_data) if compiled_walls else None
        self.reset(robot.q_home)
        #: the whole period in one compiled call, where nothing between the loop and
        #: MuJoCo needs Python (a perfect interface, no tissue, no contact pairs to follow;
        #: the coordinates mapped around it when the models' differ); None:
        #: :meth:`actuate` in Python
        self._period: CompiledPeriod | None = (
            compiled_period(self.mj_model, self.mj_data, self._actuator_dofs,
                            self.effort_limit, self.dt, self.substeps, self._compiled_ports,
                            self.joints.identity)
            if self._compiled_walls is not None and self.shaping is None
            and self.interface.mode == "off" and not self.tissues
            and self.contact_pairs is None else None)
        #: a period split in Python (a wall without a compiled form) left its last
        #: forces in ``qfrc_applied``, which the compiled period's steps would apply
        self._forces_applied = False

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
        pairs_by_geoms = (None if collisions is None
                          else add_contact_geometry(spec, robot, collisions))
        if self.tissues:
            for frame in robot.ee_frames:
                self._add_force_sensor(spec, frame)
        model = spec.compile()
        if collisions is not None and pairs_by_geoms is not None:
            self.contact_pairs = ContactPairs(collisions, pairs_by_geoms, model)
        return model

    @staticmethod
    def _add_force_sensor(spec: mujoco.MjSpec, frame: str) -> None:
        """A light tool body welded at ``frame``'s site (its centre of mass there, where
        the tissue pushes), with MuJoCo's force and torque sensors at a site on it: the
        force the EE's body exerts on the tool, in the site's (the tool's) frame."""
        site = spec.site(site_name(frame))
        tool = site.parent.add_body(name=_TOOL + frame, pos=site.pos, quat=site.quat,
                                    mass=_TOOL_MASS)
        tool.ipos = [0.0, 0.0, 0.0]
        tool.inertia = [_TOOL_MASS * _PAYLOAD_INERTIA_PER_KG] * 3
        tool.add_site(name=_TOOL + frame)
        spec.add_sensor(name=_FORCE + frame, type=mujoco.mjtSensor.mjSENS_FORCE,
                        objtype=mujoco.mjtObj.mjOBJ_SITE, objname=_TOOL + frame)
        spec.add_sensor(name=_TORQUE + frame, type=mujoco.mjtSensor.mjSENS_TORQUE,
                        objtype=mujoco.mjtObj.mjOBJ_SITE, objname=_TOOL + frame)

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
        #: the last period's measures (None: the compiled period's, made when read)
        self._last: PlantMeasures | None = PlantMeasures(np.zeros((0, 3)), np.zeros(0), 0.0,
                                                         False)

    @property
    def encoder_noise(self) -> float:
        """The encoders' declared noise std (rad), which the loop's state observer reads
        (docs/design.md 5.6)."""
        return 0.0 if self.shaping is None else self.shaping.encoder_noise

    def sense(self, q: np.ndarray) -> np.ndarray:
        """The simulated configuration ``q`` with the encoder noise on top."""
        return q if self.shaping is None else self.shaping.sense(q)

    def actuate(self, qd: np.ndarray, q: np.ndarray,
                constraints: Sequence[Constraint] = ()) -> np.ndarray:
        """Run the physics for one control period under the command ``qd`` (delayed by
        the imperfections' latency, checked by the interface, filtered by the joint lag);
        the mean velocity that takes the loop's true configuration ``q`` to the simulated
        one. With the compiled period (:mod:`teleop.plants.compiled_period`) the
        physics, the torque ratio, the contacts and the returned velocity are one C call
        with the same arithmetic, the measures made when read (:meth:`measures`)."""
        ran = self._compiled_period(qd, q, constraints)
        return ran[0] if ran is not None else self._python_period(qd, q, constraints)

    def advance(self, qd: np.ndarray, q: np.ndarray, constraints: Sequence[Constraint],
                dt: float) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`actuate`, and the configuration its velocity takes ``q`` to over ``dt``,
        ``pin.integrate(q, moved dt)``: computed by the compiled period in the same call
        (``q + moved dt``, the same bits for the 1-dof joints it serves, where the models'
        coordinates are the same) when ``dt`` is the plant's period."""
        ran = self._compiled_period(qd, q, constraints)
        if ran is not None and ran[1] is not None and dt == self.dt:
            return ran[0], ran[1]
        moved = ran[0] if ran is not None else self._python_period(qd, q, constraints)
        return moved, pin.integrate(self.model, q, moved * dt)

    def _compiled_period(self, qd: np.ndarray, q: np.ndarray,
                         constraints: Sequence[Constraint],
                         ) -> tuple[np.ndarray, np.ndarray | None] | None:
        """The period in C (:class:`~teleop.plants.compiled_period.CompiledPeriod`): the
        velocity moved and the configuration reached (None where the models' coordinates
        differ: the command mapped to MuJoCo's, the velocity from ``qpos`` mapped back as
        the Python period does), or None (nothing run: no compiled period, or a wall
        without a compiled form)."""
        period = self._period
        if period is None:
            return None
        # (the interface is off: it passes the command on, checks and counts nothing)
        if self._forces_applied:  # a period split in Python left its last forces there
            self._qfrc_applied.fill(0.0)
            self._forces_applied = False
        if self.joints.identity:
            ran = period.run(qd, q, constraints)
            if ran is None:
                return None
            self._last = None
            return ran
        if not period.run_mapped(self.joints.v_to_mujoco(qd, self._qpos), constraints):
            return None
        self._last = None
        self.joints.q_to_pinocchio(self._qpos, self._q_pin)
        return pin.difference(self.model, q, self._q_pin) / self.dt, None

    def _python_period(self, qd: np.ndarray, q: np.ndarray,
                       constraints: Sequence[Constraint]) -> np.ndarray:
        """The period in Python around ``mj_step`` (the compiled period's reference):
        :meth:`actuate`'s velocity."""
        model, data = self.mj_model, self.mj_data
        arrived = qd if self.shaping is None else self.shaping.delay(qd)
        accepted, fault = self.interface.receive(arrived)
        shaped = accepted if self.shaping is None else self.shaping.respond(accepted)
        command = self.joints.v_to_mujoco(shaped, self._qpos)
        np.take(command, self._actuator_dofs, out=self._ctrl)
        if self.contact_pairs is not None:
            self.contact_pairs.follow(model, constraints)
        holes = [(c, wall) for c in constraints if (wall := wall_of(c)) is not None]
        self._qfrc_applied.fill(0.0)
        contacts = np.zeros((len(self._tools), 3))
        depths = np.zeros(len(self._tools))
        ports = None if self.tissues or not holes else self._compiled_ports(holes)
        if ports is not None and self._compiled_walls is not None:  # one call, walls in C
            self._compiled_walls.step(model, ports, self.substeps)
            forces, springs, displacements = self._compiled_walls.results()
        elif holes or self.tissues:  # each physics step split to apply the forces there
            forces, displacements = np.zeros((len(holes), 3)), np.zeros(len(holes))
            springs = np.zeros((len(holes), 3))
            for _ in range(self.substeps):
                mujoco.mj_step1(model, data)
                data.qfrc_applied[:] = 0.0
                for i, (hole, wall) in enumerate(holes):
                    forces[i], springs[i], displacements[i] = self._push(hole, wall)
                for i in range(len(self._tools)):
                    contacts[i], depths[i] = self._press(i)
                mujoco.mj_step2(model, data)
            self._forces_applied = True
        else:  # one call: the physics steps without Python between them
            forces, displacements, springs = np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
            mujoco.mj_step(model, data, self.substeps)
        # |tau| / limit per dof in Python floats (numpy's per-call cost exceeds the sum on a
        # few dofs; the same IEEE divisions), a NaN torque kept as np.max would
        torques = [abs(tau) / limit
                   for tau, limit in zip(self._qfrc_actuator.tolist(), self._effort_limit_list)]
        ratio = max(torques) if not math.isnan(sum(torques)) else math.nan
        saturated = ratio >= 1.0 - 1e-12
        contact_count = int(data.ncon)
        penetration = 0.0 if contact_count == 0 else float(
            max(0.0, -np.min(data.contact.dist[:contact_count], initial=0.0)))
        self._last = PlantMeasures(forces, displacements, ratio, saturated, springs,
                                  contact_count, penetration,
                                  fault, self.interface.stopped, self._read_sensors(),
                                  contacts, depths)
        self.joints.q_to_pinocchio(self._qpos, self._q_pin)
        return pin.difference(self.model, q, self._q_pin) / self.dt

    def close(self) -> None:
        """Nothing to let go: the simulation lives in this process's memory."""

    def measures(self) -> PlantMeasures:
        """The last period's :class:`PlantMeasures`."""
        if self._last is None:
            self._last = self._period_measures()
        return self._last

    def _period_measures(self) -> PlantMeasures:
        """The compiled period's :class:`PlantMeasures`: its ports' results, its summary
        (what the Python path measures at the period's last physics step)."""
        assert self._period is not None  # only set to None by a compiled period
        ports, summary = self._period.ports, self._period.summary.tolist()
        ratio = summary[RATIO]
        return PlantMeasures(ports[:, FORCE:FORCE + 3].copy(),
                             ports[:, DISPLACEMENT].copy(), ratio, ratio >= 1.0 - 1e-12,
                             ports[:, SPRING:SPRING + 3].copy(), int(summary[CONTACTS]),
                             summary[PENETRATION], None, self.interface.stopped,
                             self._read_sensors(), np.zeros((0, 3)), np.zeros(0))

    # -- the tissue and the force/torque sensor ------------------------------------------

    def _press(self, ee: int) -> tuple[np.ndarray, float]:
        """Apply the tissues' force on EE ``ee``'s tool tip (at the kinematics of
        ``mj_step1``, on the tool body's centre of mass, the tip); the force (N, world) and
        the deepest penetration (m)."""
        model, data, jacobian = self.mj_model, self.mj_data, self._jacobian
        tool = self._tools[ee]
        tip = data.xipos[tool]
        mujoco.mj_jac(model, data, jacobian, None, tip, tool)
        velocity = jacobian @ data.qvel
        force = sum((tissue.force(tip, velocity) for tissue in self.tissues), np.zeros(3))
        data.xfrc_applied[tool, :3] = force + self.pushes[ee]
        return force, max(tissue.penetration(tip) for tissue in self.tissues)

    def push(self, ee: int, force: Sequence[float]) -> None:
        """Push EE ``ee``'s tool tip with ``force`` (N, world frame) from the next period on
        (a hand on the tool; the sensor reads it, ``contact_forces`` does not); needs a
        tissue (the sensor's tool body)."""
        value = np.asarray(force, dtype=float)
        if value.shape != (3,) or not np.all(np.isfinite(value)):
            raise ValueError(f"push force must be 3 finite numbers (N), got {force!r}")
        if not self.tissues:
            raise ValueError("push needs the tool body of a plant with a tissue (tissues=...)")
        self.pushes[ee] = value

    def _read_sensors(self) -> np.ndarray:
        """Each tool's wrench from the environment in its tool frame: minus MuJoCo's force
        and torque sensors (they read what the EE's body exerts on the tool, which holds
        the light tool against the tissue; computed by ``mj_step2`` at the period's last
        physics step), then the bias and the noise. The tool's own weight (1 mN) and
        inertia are in the reading, as on a real sensor."""
        wrenches = np.zeros((len(self._sensor_rows), 6))
        if not self._sensor_rows:
            return wrenches
        for i, (force, torque) in enumerate(self._sensor_rows):
            wrenches[i, :3] = -self.mj_data.sensordata[force:force + 3]
            wrenches[i, 3:] = -self.mj_data.sensordata[torque:torque + 3]
        wrenches += self.sensor_bias
        if self.sensor_noise > 0.0:
            wrenches += self._sensor_rng.normal(0.0, self.sensor_noise, wrenches.shape)
        return wrenches

    # -- the abdominal wall ----------------------------------------------------------------

    def _compiled_ports(self, holes: Sequence[tuple[Constraint, Wall]]) -> np.ndarray | None:
        """One row per hole for :class:`~teleop.plants.compiled_wall.CompiledPorts` and
        :class:`~teleop.plants.compiled_period.CompiledPeriod`: its link's MuJoCo body and
        site, then its wall's compiled parameters; None when a wall has none."""
        rows = np.empty((len(holes), 13))
        for row, (hole, wall) in zip(rows, holes):
            parameters = wall.compiled_parameters(hole)
            if parameters is None:
                return None
            site = self._site_ids[hole.link]
            row[0], row[1], row[2:] = self._site_bodies[site], site, parameters
        return rows

    def _push(self, hole: Constraint, wall: Wall) -> tuple[np.ndarray, np.ndarray, float]:
        """Apply the force of ``wall`` at ``hole`` to the instrument (at the kinematics of
        ``mj_step1``); the force (N), its spring part (``-k (P - c)`` at a port,
        :mod:`teleop.plants.walls`) and the tissue's displacement (m)."""
        model, data, jacobian = self.mj_model, self.mj_data, self._jacobian
        site = self._site_ids[hole.link]
        point, axis = wall.port(hole, data.site_xmat[site].reshape(3, 3), data.site_xpos[site])
        body = self._site_bodies[site]
        mujoco.mj_jac(model, data, jacobian, None, point, body)
        force = wall.force(hole, point, axis, jacobian @ data.qvel)
        mujoco.mj_applyFT(model, data, force, self._no_torque, point, body, data.qfrc_applied)
        return force, wall.spring(hole, point), wall.displacement(hole, point)
