"""One contact experiment (docs/design.md section 21.4): through the trocar, a tissue plane
placed ``gap`` beyond the tool tip along one axis of the tool, its normal against it; the
tool-frame hybrid law (:class:`teleop.loop.HybridForceMotion`) presses it at a setpoint
along that axis while the operator's target moves on the others (the loop's pose feedback
``K_p log6(T^-1 T*)``, a body twist); on the MuJoCo plant, for any controller. A task
(:class:`ContactTask`) says which axis, how hard, and how the operator moves: ``palpation``
and ``retraction`` are two.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from constraints import Hole
from controllers.linalg import DampingPolicy
from teleop.controller_specs import ROBOT, make_controller
from teleop.loop.hybrid_force_motion import HybridForceMotion
from teleop.loop.sensor_tare import SensorTare
from teleop.loop.tool_wrench import tool_wrench
from teleop.plants import MujocoPlant
from teleop.plants.choice import PlantChoice
from teleop.plants.tissue import TissueSurface
from teleop.robots import load_robot

#: The pose feedback's gain (1/s) and the force loop's ((m/s)/N).
POSE_GAIN, FORCE_GAIN = 20.0, 1.0
#: The force loop's speed bound (m/s): the tip meets the tissue at it.
APPROACH_SPEED = 0.01
#: The controllers' damped least squares in a contact task: a constant ``lambda`` (paper
#: eq 35), no rising part. The task's weights (rotations 0.01) scale the weighted rows'
#: smallest singular value to about the rising damping's threshold (0.01), so that damping
#: switched on and off along the path; where it switched off, the orientation error it had
#: let grow came back at once (retraction across the tool's y: 3.5 rad/s, port force 0.23 N;
#: docs/design.md 21.4).
CONTACT_DAMPING = 0.02


@dataclass(frozen=True)
class ContactTask:
    """What one contact experiment does.

    Attributes
    ----------
    name : its name.
    force_axis : the tool axis (0: x, 1: y, 2: z) under force control, the tissue's
        normal against it.
    setpoint : the force to exert along it (N).
    path : the operator target's offset at ``t`` in the tool's initial frame (m).
    window : (start, end) of the measures (s).
    duration : the default run (s).
    twist_weight : the controllers' task weight (the force axis first).
    gap : the tissue's distance beyond the tip at the start (m).
    damping : the controllers' constant DLS damping (:data:`CONTACT_DAMPING`); None: each
        controller's own (its rising damping near singularity).
    """

    name: str
    force_axis: int
    setpoint: float
    path: Callable[[float], np.ndarray]
    window: tuple[float, float]
    duration: float
    twist_weight: tuple[float, ...]
    gap: float = 2e-3
    damping: float | None = CONTACT_DAMPING


@dataclass
class ContactMeasures:
    """Over the task's window (:attr:`ContactTask.window`) unless said.

    Attributes
    ----------
    force_error_rms, force_error_max : ``| |f_contact| - f_d |`` from the plant's true
        contact force (N).
    contact_lost : periods of the window with the tip out of the tissue.
    port_force_max : the wall's largest force on the instrument (N), whole run.
    hole_error_max : the hole's largest error at the true configuration (m), whole run.
    ee_error_max : the largest tool-tip error from the target across the force axis (m),
        from the window's start.
    jerk_max : the largest joint jerk of the commands (rad/s^3), finite differences.
    sensed_vs_true_max : the largest difference between the sensor's force (world) and the
        true contact force (N), the tool's weight included.
    interface_faults : the periods whose command the plant's interface refused
        (``strict``: at most one, the robot stopped there) or counted (``count``); None:
        the interface checks nothing (``off``, docs/design.md 17.1).
    """

    force_error_rms: float
    force_error_max: float
    contact_lost: int
    port_force_max: float
    hole_error_max: float
    ee_error_max: float
    jerk_max: float
    sensed_vs_true_max: float
    forces: np.ndarray
    times: np.ndarray
    interface_faults: int | None = None


def run_contact(task: ContactTask, spec: str, dt: float = 1e-3,
                duration: float | None = None,
                sensor_noise: float = 0.0, sensor_bias: Sequence[float] | None = None,
                seed: int = 0, tare_samples: int = 0, plant: PlantChoice | None = None,
                acceleration_limits: bool = False, jerk_limit: float | None = None,
                force_filter: float | None = None) -> ContactMeasures:
    """Run ``task`` (for ``duration`` s, default its own) with controller ``spec``
    (``cjm``, ``qp:daqp``, ``mink:daqp``...),
    the force/torque sensor's noise, bias and seed as :class:`~teleop.plants.MujocoPlant`
    takes them; ``tare_samples`` > 0: the reading is tared over that many periods first,
    the tool held out of contact meanwhile (:class:`~teleop.loop.sensor_tare.SensorTare`).
    ``plant``: the physics settings and the abdominal wall's stiffness (None: the
    defaults; it must be the mujoco plant, the only one with a force/torque sensor);
    ``acceleration_limits``: the controller keeps the robot's, ``jerk_limit`` (rad/s^3)
    one on every joint (docs/design.md 8.4, 8.5); ``force_filter``: the cut-off (Hz) of the
    law's two-section low-pass filter on the sensed wrench (None: none; docs/design.md
    21.3)."""
    duration = task.duration if duration is None else duration
    axis = task.force_axis
    robot = load_robot("sda10f")
    model, data = robot.model, robot.model.createData()
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.08)
    plant_choice = plant or PlantChoice("mujoco")
    if plant_choice.kind != "mujoco":
        raise ValueError(f"{task.name} needs the mujoco plant: the {plant_choice.kind} plant has "
                         f"no force/torque sensor at the tool (docs/design.md 21.2)")
    plant_choice.apply_wall([hole])
    frame = robot.ee_frame_id
    pin.framesForwardKinematics(model, data, q)
    start = data.oMf[frame].copy()
    tissue = TissueSurface(start.translation + task.gap * start.rotation[:, axis],
                           -start.rotation[:, axis])
    physics = MujocoPlant(robot, dt, plant_choice.settings, tissues=[tissue],
                          sensor_noise=sensor_noise, sensor_bias=sensor_bias, seed=seed)
    controller = make_controller(spec, robot, [hole], dt=dt, twist_weight=task.twist_weight,
                                 time_budget=None,
                                 acceleration_limit=ROBOT if acceleration_limits else None,
                                 jerk_limit=jerk_limit)
    if task.damping is not None:
        controller.policy = DampingPolicy(task.damping, 0.0, 0.0)
    selection = tuple(i == axis for i in range(3))
    law = HybridForceMotion(selection, [task.setpoint if chosen else 0.0 for chosen in selection],
                            FORCE_GAIN,
                            tissue.stiffness, dt, max_speed=APPROACH_SPEED,
                            filter_cutoff=force_filter)
    if duration < task.window[0] + dt:
        raise ValueError(f"{task.name}: duration {duration:g} s ends before its measures' "
                         f"window starts at {task.window[0]:g} s")
    steps = int(round(duration / dt))
    times = np.arange(1, steps + 1) * dt
    forces, lost = np.zeros(steps), 0
    port, hole_error, ee_error, sensed_error = 0.0, 0.0, 0.0, 0.0
    faults = 0
    commands = np.zeros((steps, model.nv))
    wrench = np.zeros(6)
    tare = SensorTare(tare_samples) if tare_samples > 0 else None
    begin, end = task.window
    for n in range(steps):
        t = n * dt
        pin.framesForwardKinematics(model, data, q)
        tool = data.oMf[frame]
        target = pin.SE3(start.rotation, start.translation + start.rotation @ task.path(t))
        operator = POSE_GAIN * pin.log6(tool.actInv(target)).vector
        across = target.translation - tool.translation
        across -= (across @ tool.rotation[:, axis]) * tool.rotation[:, axis]
        if t >= begin:
            ee_error = max(ee_error, float(np.linalg.norm(across)))
        held = tare is not None and not tare.done  # out of contact while taring
        qd = controller.solve(q, operator if held else law.twist(operator, wrench))
        commands[n] = qd
        q = pin.integrate(model, q, physics.actuate(qd, q, [hole]) * dt)
        measures = physics.measures()
        wrench = tool_wrench(physics, 0) if tare is None else tare(tool_wrench(physics, 0))
        forces[n] = float(np.linalg.norm(measures.contact_forces[0]))
        pin.framesForwardKinematics(model, data, q)
        rotation = data.oMf[frame].rotation
        sensed_error = max(sensed_error, float(np.linalg.norm(
            rotation @ wrench[:3] - measures.contact_forces[0])))
        port = max(port, measures.port_force)
        faults += measures.interface_fault is not None
        hole_error = max(hole_error, float(np.linalg.norm(
            hole.error(data.oMf[model.getFrameId(hole.link)]))))
        if begin <= t <= end and measures.contact_depths[0] <= 0.0:
            lost += 1
    window = (times >= begin) & (times <= end)
    error = np.abs(forces[window] - task.setpoint)
    jerk = np.diff(commands, n=2, axis=0) / dt ** 2
    checked = plant_choice.settings.interface_limits != "off"
    return ContactMeasures(float(np.sqrt(np.mean(error ** 2))), float(np.max(error)), lost,
                           port, hole_error, ee_error, float(np.max(np.abs(jerk))),
                           sensed_error, forces, times, faults if checked else None)
