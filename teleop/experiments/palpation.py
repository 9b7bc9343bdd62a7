"""The ``palpation`` experiment (docs/design.md section 21.4): through the trocar, the tool
tip presses a tissue surface at 1 N along the tool's axis and slides 2 cm across it and
back, under the tool-frame hybrid law (:class:`teleop.loop.HybridForceMotion`) on the
MuJoCo plant, for any controller.

The SDA10F with the paper's hole on link 6; the tissue plane 2 mm beyond the tool tip at
the start, its normal against the tool's z axis (the instrument's), so the force loop
along the tool's z first closes the gap and presses (at most 1 cm/s), then holds 1 N (a
15 mm penetration of the default tissue). After 2.5 s the operator's target
slides along the tool's x at the start, ``s(t) = 2 cm (1 - cos(2 pi (t - 2.5) / 4)) / 2`` for
4 s (out and back), the orientation held; the loop's pose feedback
``K_p log6(T^-1 T*)`` (body twist) gives the twist on the free axes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from constraints import Hole
from teleop.controller_specs import ROBOT, make_controller
from teleop.loop.hybrid_force_motion import HybridForceMotion
from teleop.loop.sensor_tare import SensorTare
from teleop.loop.tool_wrench import tool_wrench
from teleop.plants import MujocoPlant
from teleop.plants.choice import PlantChoice
from teleop.plants.tissue import TissueSurface
from teleop.robots import load_robot

#: One line for humans (``teleop scenarios``).
DESCRIPTION = ("through the trocar, the tip presses tissue at 1 N along the tool and slides 2 cm "
               "across it and back (hybrid force/motion; the mujoco plant)")
#: The force the tool exerts along its z (N), the slide (m), the phases (s).
SETPOINT, SLIDE, SETTLE, SLIDE_TIME = 1.0, 0.02, 2.5, 4.0
#: The pose feedback's gain (1/s) and the force loop's ((m/s)/N).
POSE_GAIN, FORCE_GAIN = 20.0, 1.0
#: The force loop's speed bound (m/s): the tip meets the tissue at it.
APPROACH_SPEED = 0.01
#: The task's weight: the force axis (tool z) first where the twist is not feasible.
TWIST_WEIGHT = (1.0, 1.0, 100.0, 0.01, 0.01, 0.01)


@dataclass
class PalpationMeasures:
    """Over the slide (``t`` in [2.5 s, 6.5 s]) unless said.

    Attributes
    ----------
    force_error_rms, force_error_max : ``| |f_contact| - 1 N |`` from the plant's true
        contact force (N).
    contact_lost : periods of the slide with the tip out of the tissue.
    port_force_max : the wall's largest force on the instrument (N), whole run.
    hole_error_max : the hole's largest error at the true configuration (m), whole run.
    ee_error_max : the largest tool-tip error from the target across the tool's z (m).
    jerk_max : the largest joint jerk of the commands (rad/s^3), finite differences.
    sensed_vs_true_max : the largest difference between the sensor's force (world) and the
        true contact force (N), the tool's weight included.
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


def slide(t: float) -> float:
    """The target's offset along the tool's initial x at ``t`` (m)."""
    if t <= SETTLE or t >= SETTLE + SLIDE_TIME:
        return 0.0
    return SLIDE * 0.5 * (1.0 - math.cos(2.0 * math.pi * (t - SETTLE) / SLIDE_TIME))


def run_palpation(spec: str, dt: float = 1e-3, duration: float = SETTLE + SLIDE_TIME + 0.5,
                  sensor_noise: float = 0.0, sensor_bias: Sequence[float] | None = None,
                  seed: int = 0, tare_samples: int = 0, plant: PlantChoice | None = None,
                  acceleration_limits: bool = False,
                  jerk_limit: float | None = None,
                  force_filter: float | None = None) -> PalpationMeasures:
    """Run the experiment with controller ``spec`` (``cjm``, ``qp:daqp``, ``mink:daqp``...),
    the force/torque sensor's noise, bias and seed as :class:`~teleop.plants.MujocoPlant`
    takes them; ``tare_samples`` > 0: the reading is tared over that many periods first,
    the tool held out of contact meanwhile (:class:`~teleop.loop.sensor_tare.SensorTare`).
    ``plant``: the physics settings and the abdominal wall's stiffness (None: the
    defaults; it must be the mujoco plant, the only one with a force/torque sensor);
    ``acceleration_limits``: the controller keeps the robot's, ``jerk_limit`` (rad/s^3)
    one on every joint (docs/design.md 8.4, 8.5); ``force_filter``: the cut-off (Hz) of the
    law's two-section low-pass filter on the sensed wrench (None: none; docs/design.md
    21.3)."""
    robot = load_robot("sda10f")
    model, data = robot.model, robot.model.createData()
    q = robot.q_home.copy()
    hole = Hole.on_link(robot, q, distance=0.08)
    plant_choice = plant or PlantChoice("mujoco")
    if plant_choice.kind != "mujoco":
        raise ValueError(f"palpation needs the mujoco plant: the {plant_choice.kind} plant has "
                         f"no force/torque sensor at the tool (docs/design.md 21.2)")
    plant_choice.apply_wall([hole])
    frame = robot.ee_frame_id
    pin.framesForwardKinematics(model, data, q)
    start = data.oMf[frame].copy()
    tissue = TissueSurface(start.translation + 2e-3 * start.rotation[:, 2],
                           -start.rotation[:, 2])
    physics = MujocoPlant(robot, dt, plant_choice.settings, tissues=[tissue],
                          sensor_noise=sensor_noise, sensor_bias=sensor_bias, seed=seed)
    controller = make_controller(spec, robot, [hole], dt=dt, twist_weight=TWIST_WEIGHT,
                                 time_budget=None,
                                 acceleration_limit=ROBOT if acceleration_limits else None,
                                 jerk_limit=jerk_limit)
    law = HybridForceMotion((False, False, True), (0.0, 0.0, SETPOINT), FORCE_GAIN,
                            tissue.stiffness, dt, max_speed=APPROACH_SPEED,
                            filter_cutoff=force_filter)
    steps = int(round(duration / dt))
    times = np.arange(1, steps + 1) * dt
    forces, lost = np.zeros(steps), 0
    port, hole_error, ee_error, sensed_error = 0.0, 0.0, 0.0, 0.0
    commands = np.zeros((steps, model.nv))
    wrench = np.zeros(6)
    tare = SensorTare(tare_samples) if tare_samples > 0 else None
    for n in range(steps):
        t = n * dt
        pin.framesForwardKinematics(model, data, q)
        tool = data.oMf[frame]
        target = pin.SE3(start.rotation, start.translation + slide(t) * start.rotation[:, 0])
        operator = POSE_GAIN * pin.log6(tool.actInv(target)).vector
        across = target.translation - tool.translation
        across -= (across @ tool.rotation[:, 2]) * tool.rotation[:, 2]
        if t >= SETTLE:
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
        hole_error = max(hole_error, float(np.linalg.norm(
            hole.error(data.oMf[model.getFrameId(hole.link)]))))
        if SETTLE <= t <= SETTLE + SLIDE_TIME and measures.contact_depths[0] <= 0.0:
            lost += 1
    window = (times >= SETTLE) & (times <= SETTLE + SLIDE_TIME)
    error = np.abs(forces[window] - SETPOINT)
    jerk = np.diff(commands, n=2, axis=0) / dt ** 2
    return PalpationMeasures(float(np.sqrt(np.mean(error ** 2))), float(np.max(error)), lost,
                             port, hole_error, ee_error, float(np.max(np.abs(jerk))),
                             sensed_error, forces, times)
