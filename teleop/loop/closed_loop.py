"""The closed teleoperation loop: operator target -> EE twist -> controller -> integrate.

One tick (docs/design.md section 5), for every end effector ``i`` of ``robot.ee_frames``::

    T*_i    <- the supervised target: moved by s times the operator's motion (section 5.2)
    T*_f,i <- T*_f,i exp6(alpha log6(T*_f,i^-1 T*_i))   target smoothing (browser: ~20 Hz input)
    V_ff,i  = log6(T*_f,i,prev^-1 T*_f,i) / dt           feed-forward: the target's own twist
    V_e,i   = K_p log6(T_e,i^-1 T*_f,i) + Ad V_ff,i      EE body twist, then saturated
    qd      = controller.solve(q, [V_e,1; V_e,2; ...])   stacked, 6 per EE (section 11)
    q      <- pin.integrate(model, q, qd dt)             nq != nv on a mobile base

(the smoothing, the twists and their caps are the :class:`PoseServo`'s,
:mod:`teleop.loop.pose_servo`), and every tick records the measures of docs/design.md
section 7, computed here from Pinocchio and the constraints themselves, not taken from the
controller's own report.

A controller that can run that hot path in C++ offers it (``controller.loop_tick``, the
CJM's compiled backend); the loop then runs a period in one call and keeps the Python
path below as the reference, taken when ``compiled_tick=False`` or when the controller's
step cannot tick compiled (docs/design.md section 5.1).

A :class:`Plant` (docs/design.md section 15.1) may stand between the loop and the robot's
true joints: the loop then computes the command from the configuration the plant senses,
and the robot moves with the joint velocity the plant applies; the measures stay on the
true configuration. With a calibration error (``true_model``), the measures take the true
kinematics there too (:mod:`teleop.loop.true_kinematics`); the hot path stays the
controller's, on the model.
"""

from __future__ import annotations

import math
import time
from typing import Callable, Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.collision import CollisionAvoidance
from constraints.kinematics import frame_placement
from constraints.validation import as_vector
from controllers.step_message import StepMessage

from .constraint_measures import (constraint_errors, constraint_velocity, norm,
                                  relative_rotations)
from .distance_meter import DistanceMeter
from .loop_config import LoopConfig
from .measured_in_batches import Kinematics, measure_periods
from .measured_later import Geometry, MeasuredLater, geometry_copy
from .naming import constraint_names, row_labels
from .plant import Advance, Plant, advance_of
from .pose_servo import PoseServo
from .records import CompiledPendingStep, PendingStep, StepRecord, step_record
from .state_observer import StateObserver
from .supervisor import Supervision, Supervisor
from .targets import Targets, target_poses
from .task_modes import fit_target, task_modes as checked_task_modes, task_weight
from .true_kinematics import TrueKinematics

#: the message of a period whose command came out non-finite (the loop stops instead)
NON_FINITE_STOP = StepMessage.worded("non-finite command replaced by a stop")


class TeleopLoop:
    """State and one-tick logic of the closed loop; no threads, no I/O.

    Parameters
    ----------
    robot : a ``teleop.Robot``.
    controller : any controller with ``solve(q, twist)``, ``step_outcome()``, ``info`` and
        ``set_constraints``.
    q0 : initial configuration (default ``robot.q_home``).
    config : :class:`LoopConfig`.
    plant : what stands between the loop and the true joints (:class:`Plant`,
        docs/design.md section 15.1); None: the loop reads and drives them exactly.
    collisions : a collision avoidance of the loop's own (not the controller's) whose
        pairs' minimum distance every period measures at the true configuration
        (:class:`~teleop.loop.distance_meter.DistanceMeter`, docs/design.md 18.6); None:
        not measured.
    compiled_tick : run the hot path compiled (one C++ call a period:
        ``controller.loop_tick``, the CJM's compiled backend) when the controller offers
        it; False: always the Python path, the readable reference (docs/design.md 5.1).
    true_model : the real robot's kinematics when they differ from ``robot.model`` (a
        calibration error, docs/design.md section 15.1); the measures take them
        (:class:`~teleop.loop.true_kinematics.TrueKinematics`), the controller and the hot
        path keep the model. None: the model is the robot.
    task_modes : what the operator commands of each EE (docs/design.md section 20), one
        mode or one per EE; each target is fitted to its mode before the filter. The
        controller is built with their rows as its weight, or :meth:`set_task_modes`.

    Targets (:data:`Targets`) are one ``pin.SE3`` per entry of ``robot.ee_frames``, in
    that order; a single-EE robot also takes the pose alone.
    """

    def __init__(self, robot, controller, q0: np.ndarray | None = None,
                 config: LoopConfig | None = None, plant: Plant | None = None,
                 collisions: CollisionAvoidance | None = None,
                 compiled_tick: bool = True, true_model: pin.Model | None = None,
                 task_modes: str | Sequence[str] = "pose") -> None:
        self.robot = robot
        self.model: pin.Model = robot.model
        self.data: pin.Data = self.model.createData()
        #: the measures' kinematics when the robot is not its model (None: the model's)
        self.true_kinematics = (None if true_model is None
                                else TrueKinematics(self.model, true_model))
        self.controller = controller
        if config is not None and not isinstance(config, LoopConfig):
            raise ValueError(f"config must be a LoopConfig, got {type(config).__name__}")
        self.config = config or LoopConfig()
        self.plant = plant
        #: the minimum distance's meter and its counts (None: not measured)
        self.distance_meter = None if collisions is None else DistanceMeter(collisions)
        self.ee_frame_ids: tuple[int, ...] = tuple(self.model.getFrameId(name)
                                                   for name in robot.ee_frames)
        self.ee_frame_id = self.ee_frame_ids[0]
        #: the task mode of each EE; whether any fits its target (not the full pose)
        self.task_modes = checked_task_modes(task_modes, len(self.ee_frame_ids))
        self._fitting = any(mode != "pose" for mode in self.task_modes)
        self.q = as_vector(robot.q_home if q0 is None else q0, self.model.nq, "q0")
        if plant is not None:
            plant.reset(self.q)
        #: measures the sensed robot, scales the operator's motion into the target the
        #: loop follows; what it did last (docs/design.md 5.2)
        self.supervisor = Supervisor(self.model, self.config.supervisor, self.config.dt)
        self.supervision: Supervision | None = None
        #: the configuration the loop takes from the encoders (docs/design.md 5.6); the
        #: plant's declared encoder noise sets its gain
        self.observer: StateObserver = self.config.state_observer.observer(
            self.model, float(getattr(plant, "encoder_noise", 0.0)), self.config.dt)
        self.t = 0.0
        #: the targets to the EE twists: filter, law, caps and the filter's state
        #: (:class:`PoseServo`, docs/design.md 5.1)
        self.servo = PoseServo(self.config, len(self.ee_frame_ids))
        #: the hot path compiled around the controller's step, when it offers one and
        #: ``compiled_tick`` (docs/design.md 5.1): the servo's kernel; None: the Python
        #: path below
        self.compiled = self.servo.attach_kernel(controller) if compiled_tick else None
        #: the supervisor reads the compiled tick's measures: its kinematics are this model's
        self._sensed_compiled = getattr(controller, "model", None) is self.model
        self.last_qd = np.zeros(self.model.nv)
        self.refused = ""  # why the controller refused the last input (ValueError), if it did
        self._labels_key: tuple[int, ...] = ()
        self._labels: tuple[str, ...] = ()
        self._names: tuple[str, ...] = ()
        if self.distance_meter is not None:
            self.distance_meter.set_constraints(self.constraints)

    # -- state -------------------------------------------------------------------------

    @property
    def previous_targets(self) -> list[pin.SE3] | None:
        """The filtered targets of the last period (their feed-forward), None at the start."""
        return self.servo.previous

    @property
    def plant(self) -> Plant | None:
        """What stands between the loop and the true joints (None: the perfect robot)."""
        return self._plant

    @plant.setter
    def plant(self, plant: Plant | None) -> None:
        self._plant = plant
        self._advance: Advance | None = None if plant is None else advance_of(plant, self.model)

    @property
    def constraints(self) -> list[Constraint]:
        return self.controller.constraints

    def set_constraints(self, constraints: Sequence[Constraint]) -> None:
        self.controller.set_constraints(list(constraints))
        if self.distance_meter is not None:
            self.distance_meter.set_constraints(self.constraints)

    def set_task_modes(self, task_modes: str | Sequence[str],
                       twist_weight: np.ndarray | None = None) -> None:
        """What the operator commands of each EE from now on (docs/design.md section 20),
        the controller's task weight with it: ``twist_weight``, or the modes' rows
        (:func:`~teleop.loop.task_modes.task_weight`). ``ValueError`` changes nothing."""
        modes = checked_task_modes(task_modes, len(self.ee_frame_ids))
        self.controller.twist_weight = task_weight(modes) if twist_weight is None else twist_weight
        self.task_modes, self._fitting = modes, any(mode != "pose" for mode in modes)

    def ee_placement(self, q: np.ndarray | None = None) -> pin.SE3:
        """World placement of the first EE at ``q`` (default: the current state)."""
        return frame_placement(self.model, self.q if q is None else q, self.ee_frame_id, self.data)

    def ee_placements(self, q: np.ndarray | None = None) -> list[pin.SE3]:
        """World placement of every EE at ``q`` (default: the current state), in
        ``robot.ee_frames`` order."""
        pin.framesForwardKinematics(self.model, self.data, self.q if q is None else q)
        return [self.data.oMf[frame].copy() for frame in self.ee_frame_ids]

    def reset(self, q0: np.ndarray | None = None) -> None:
        """Back to ``q0`` (default home), forgetting the target history (and the plant's
        commands in flight, and the controller's previous command: its acceleration limits
        start again from rest)."""
        self.controller.reset()
        self.q = np.array(self.robot.q_home if q0 is None else q0, dtype=float)
        self.t = 0.0
        self.servo.reset()
        self.last_qd = np.zeros(self.model.nv)
        self.supervisor.reset()
        self.supervision = None
        self.observer.reset()
        if self.plant is not None:
            self.plant.reset(self.q)
        if self.distance_meter is not None:
            self.distance_meter.reset()

    def hold(self, ee: int, pose: pin.SE3) -> None:
        """EE ``ee``'s filtered target and its feed-forward at ``pose``: the next command
        asks it no motion but towards ``pose`` (a watchdog's stop, docs/design.md 19.2)."""
        self.servo.hold(ee, pose)
        self.supervisor.hold(ee, pose)

    # -- one tick ----------------------------------------------------------------------

    def targets(self, target: Targets) -> list[pin.SE3]:
        """``target`` as one pose per EE; ``ValueError`` unless it has one per
        ``robot.ee_frames`` entry (a lone ``pin.SE3`` counts as one)."""
        if len(self.ee_frame_ids) == 1 and isinstance(target, pin.SE3):  # the common case
            return [target]
        poses = target_poses(target)
        if len(poses) != len(self.ee_frame_ids):
            raise ValueError(f"expected {len(self.ee_frame_ids)} target poses, one per EE frame "
                             f"{list(self.robot.ee_frames)}, got {len(poses)}")
        return poses

    def tick(self, target: Targets,
             advance_geometry: Callable[[float], None] | None = None) -> StepRecord:
        """Advance one control period towards ``target`` (one pose per EE) and measure it.

        The hot path (:meth:`advance`) is what a robot's control loop runs; the measures
        come after it, off that path (docs/design.md section 5.1): the command's at the
        state it was computed for (:meth:`measure_command`), then, once
        ``advance_geometry(t)`` (when moving geometry is given) has moved the constraints
        to the new time, the end-of-period ones against the geometry of that instant
        (:meth:`measure`).
        """
        step = self.advance(target)
        self.measure_command(step)
        if advance_geometry is not None:
            advance_geometry(self.t)
        return self.measure(step)

    @property
    def measures_later(self) -> bool:
        """Whether :meth:`tick_measured_later` leaves the measures for later: not with a
        calibration error (the true kinematics register each constraint object where it is
        first met) nor with a distance meter (its counts and ports follow the run)."""
        return self.true_kinematics is None and self.distance_meter is None

    def tick_measured_later(self, target: Targets,
                            advance_geometry: Callable[[float], None] | None = None,
                            ) -> MeasuredLater:
        """:meth:`tick`'s period with its measures left for :meth:`measure_later`, which
        gives the same record (docs/design.md 5.1, :mod:`teleop.loop.measured_later`):
        the hot path, then what the measures read, kept: the geometry at the command and,
        once ``advance_geometry(t)`` has moved it, at the end (the command's when there is
        none: nothing moves it in between). Where the measures cannot wait
        (:attr:`measures_later`), they are taken now and kept."""
        step = self.advance(target)
        if not self.measures_later:
            self.measure_command(step)
            if advance_geometry is not None:
                advance_geometry(self.t)
            record = self.measure(step)
            geometry = self._geometry()
            return MeasuredLater(step, geometry, geometry, self.q, self.t, record.plant, record)
        command = end = self._geometry()
        if advance_geometry is not None:
            advance_geometry(self.t)
            end = self._geometry()
        return MeasuredLater(step, command, end, self.q, self.t,
                             None if self.plant is None else self.plant.measures())

    def measure_later(self, period: MeasuredLater) -> StepRecord:
        """The record of a period of :meth:`tick_measured_later` (:meth:`measure_all_later`
        of that period alone)."""
        return self.measure_all_later([period])[0]

    def measure_all_later(self, periods: Sequence[MeasuredLater]) -> list[StepRecord]:
        """The records of periods of :meth:`tick_measured_later`, in their order: the
        measures of :meth:`measure_command` and :meth:`measure` at what each period kept,
        taken over all of them at once (:mod:`teleop.loop.measured_in_batches`), or the
        record taken then, where they could not wait."""
        pending = [period for period in periods if period.record is None]
        kinematics = Kinematics(self.model, self.data, self.ee_frame_ids, self.config.dt,
                                self.plant is not None)
        measured = iter(measure_periods(kinematics, pending))
        return [next(measured) if period.record is None else period.record
                for period in periods]

    def _geometry(self) -> Geometry:
        """The constraints as they are now (:class:`Geometry`)."""
        labels = self._row_labels()
        return Geometry(tuple(map(geometry_copy, self.constraints)),
                        self.controller.constraint_frames, self._names, labels)

    def advance(self, target: Targets) -> PendingStep:
        """The hot path of a period: the supervisor (:meth:`supervise`: its measures, the
        supervised targets), filter the targets, the EE poses, the command, the
        controller's step, the integration. No measures (:meth:`measure_command`).

        It runs compiled (:attr:`compiled`, one C++ call) when the controller offers it
        and its current step can take it; else, and on a period whose sensed
        configuration the C++ side does not take, the Python reference
        (:meth:`_advance_python`), to which the filter's state is handed over."""
        tick_start = time.perf_counter_ns()
        sensed = (self.q if self.plant is None
                  else self.observer.estimate(self.plant.sense(self.q), self.last_qd))
        compiled = self.compiled
        ready = compiled is not None and compiled.ready()
        supervision = self.supervise(sensed, self.targets(target),
                                     compiled.sense(sensed) if ready and self._sensed_compiled
                                     else None)
        poses = self.supervisor.followed_targets
        if self._fitting:  # each target fitted at its EE's sensed pose (section 20.2)
            pin.forwardKinematics(self.model, self.data, sensed)
            poses = [fit_target(mode, pose, pin.updateFramePlacement(self.model, self.data, frame))
                     for mode, pose, frame in zip(self.task_modes, poses, self.ee_frame_ids)]
        if ready:
            try:
                result = self.servo.run_kernel(poses, sensed, self.plant is None)
            except ValueError:  # a declaration refused: the Python path's controlled stop
                result = None
            if result is not None:
                return self._advance_compiled(result, sensed, tick_start).supervised_by(
                    supervision)
        return self._advance_python(poses, sensed, tick_start).supervised_by(supervision)

    def supervise(self, sensed: np.ndarray, operator_targets: list[pin.SE3],
                  errors: list[float] | None = None) -> Supervision:
        """The supervisor's measures at ``sensed`` (``errors``: each constraint's
        violation there when the compiled tick measured them, else the supervisor's own)
        and of the plant's port forces, and its action: the operator's motion to
        ``operator_targets`` scaled into the targets the loop follows,
        ``self.supervisor.followed_targets`` (docs/design.md 5.2); kept in
        :attr:`supervision`."""
        measures = None if self.plant is None else self.plant.measures()
        self._row_labels()  # the constraints' names, when the set changed
        self.supervision = self.supervisor.supervise(
            sensed, operator_targets, self.constraints, self.controller.constraint_frames,
            self._names, getattr(measures, "port_forces", None), errors)
        return self.supervision

    def _advance_python(self, poses: list[pin.SE3], sensed: np.ndarray,
                        tick_start: int) -> PendingStep:
        """The period in Python (the reference): Pinocchio's kinematics for the EE poses,
        the twists, the solve, ``pin.integrate``."""
        model, data = self.model, self.data
        pin.forwardKinematics(model, data, sensed)
        placements = [pin.updateFramePlacement(model, data, frame).copy()
                      for frame in self.ee_frame_ids]
        servo = self.servo.period(poses, placements)
        qd, status, message, step_time = self._solve(sensed, np.concatenate(servo.twists))
        q_before, qd, moved, status, message = self._move(sensed, qd, status, message)
        return PendingStep(
            targets=servo.targets, previous_targets=servo.previous, placements=placements,
            twists=servo.twists, sensed=sensed, q_before=q_before, qd=qd, moved=moved,
            tick_time_us=(time.perf_counter_ns() - tick_start) * 1e-3, step_time_us=step_time,
            status=status, step_message=message, twist_saturated=servo.saturated)

    def _advance_compiled(self, result: tuple, sensed: np.ndarray,
                          tick_start: int) -> PendingStep:
        """The rest of a period the compiled tick ran (``result``: its ``TickResult``): a
        refused twist goes to the controller (which says why, a controlled stop
        follows), a plant moves the robot, else the tick's own integration is the next
        configuration."""
        _, qd, next_q, period, step_time, saturated, has_previous = result
        if qd is None:  # a twist that is not finite: the controller refuses it, says why
            qd, status, message, step_time = self._solve(sensed, self.compiled.twist.copy())
        else:
            outcome, message = self.controller.step_outcome()
            status = outcome.value
            self.refused = ""
        if next_q is None:  # a plant, or a command to check
            q_before, qd, moved, status, message = self._move(sensed, qd, status, message)
        else:  # the tick integrated its finite command
            q_before, moved, self.q, self.last_qd = self.q, qd, next_q, qd
            self.t += self.config.dt
        return CompiledPendingStep(period, has_previous, sensed, q_before, qd, moved,
                                   (time.perf_counter_ns() - tick_start) * 1e-3, step_time,
                                   status, message, saturated)

    def _solve(self, sensed: np.ndarray,
               twist: np.ndarray) -> tuple[np.ndarray, str, StepMessage, float]:
        """``controller.solve``: the command, its status and message (worded when read,
        ``controller.step_outcome``), its time (us); a refused input (``ValueError``)
        gives the controlled stop, ``failed`` and why, and the pose servo starts over (a
        target that was not finite would stay in its filter: the next finite target is
        then a first one, docs/design.md 5.1)."""
        solve_start = time.perf_counter_ns()
        try:
            qd = self.controller.solve(sensed, twist)
            outcome, message = self.controller.step_outcome()
            status = outcome.value
            self.refused = ""
        except ValueError as error:  # refused input: a controlled stop, say why
            qd, status, self.refused = self._stop(sensed), "failed", str(error)
            message = StepMessage.worded(self.refused)
            self.servo.reset()
        return qd, status, message, (time.perf_counter_ns() - solve_start) * 1e-3

    def _move(self, sensed: np.ndarray, qd: np.ndarray, status: str,
              message: StepMessage,
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, str, StepMessage]:
        """Never a non-finite command (a stop instead); the plant moves the robot, or the
        command itself; ``q <- integrate(q, moved dt)`` (the plant's :meth:`Plant.advance`
        gives both). Returns the configuration
        before, the command, the velocity moved with, the status and the message."""
        if not math.isfinite(sum(qd.tolist())):  # never integrate a non-finite command
            qd, status, message = self._stop(sensed), "failed", NON_FINITE_STOP
        q_before = self.q
        if self._advance is None:
            moved, self.q = qd, pin.integrate(self.model, q_before, qd * self.config.dt)
        else:
            moved, self.q = self._advance(qd, q_before, self.constraints, self.config.dt)
        self.last_qd = qd
        self.t += self.config.dt
        return q_before, qd, moved, status, message

    def _stop(self, sensed: np.ndarray) -> np.ndarray:
        """The controller's controlled stop at ``sensed`` (inside its velocity, position and
        acceleration box), or zero when even that is not finite (a non-finite ``sensed``)."""
        command = self.controller.stop(sensed)
        return command if math.isfinite(sum(command.tolist())) else np.zeros(self.model.nv)

    def measure_command(self, step: PendingStep) -> None:
        """The command's measures, into ``step``, at the state and geometry it was computed
        for: its residual ``max |A qd - b|`` at the sensed configuration; the velocities
        the joints moved with at the true one (each equality row's ``C v_c`` relative to
        its geometry, the drift ``-K e``, the EE velocities), with the true kinematics when
        they differ (:meth:`_measured_kinematics`); the operator's and the commanded EE
        velocities (world)."""
        constraints: Sequence[Constraint] = self.constraints
        frames = self.controller.constraint_frames
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, step.sensed)  # the frames: where they are read
        step.residual, step.constraint_velocity, step.drift_velocity, step.floor = \
            constraint_velocity(step.qd, model, data, constraints, frames)
        if self.plant is not None or self.true_kinematics is not None:
            model, data, constraints = self._measured_kinematics(step.q_before, constraints,
                                                                 frames)
            pin.computeJointJacobians(model, data, step.q_before)
            _, step.constraint_velocity, step.drift_velocity, step.floor = \
                constraint_velocity(step.moved, model, data, constraints, frames)
        step.actual_linear_velocities = np.array([
            pin.updateFramePlacement(model, data, frame).rotation
            @ (pin.getFrameJacobian(model, data, frame, pin.LOCAL)[:3] @ step.moved)
            for frame in self.ee_frame_ids])
        step.commanded_linear_velocities = np.array(
            [ee.rotation @ twist[:3] for ee, twist in zip(step.placements, step.twists)])
        dt, now = self.config.dt, step.target_translations
        before = step.previous_translations
        step.operator_linear_velocities = (np.zeros((len(now), 3)) if before is None
                                           else np.array([(position - previous) / dt
                                                          for position, previous in zip(now, before)]))
        step.labels = self._row_labels()

    def measure(self, step: PendingStep) -> StepRecord:
        """The end of the period's measures (after :meth:`measure_command`), at the true
        configuration with the true kinematics (:meth:`_measured_kinematics`)."""
        self._row_labels()  # the names, when the set changed
        q, frames = self.q, self.controller.constraint_frames
        model, data, constraints = self._measured_kinematics(q, self.constraints, frames)
        pin.forwardKinematics(model, data, q)  # the frames read below, not every frame
        placements = [pin.updateFramePlacement(model, data, frame) for frame in self.ee_frame_ids]
        errors, error, penetration = constraint_errors(model, data, constraints, frames)
        position_errors = np.array([norm(ee.translation - target)
                                    for ee, target in zip(placements, step.target_translations)])
        orientation_errors = np.array([norm(pin.log3(relative_rotations(ee.rotation, target)))
                                       for ee, target in zip(placements, step.target_rotations)])
        violation = max(0.0, *(q - model.upperPositionLimit).tolist(),
                        *(model.lowerPositionLimit - q).tolist())
        distance = (None if self.distance_meter is None
                    else self.distance_meter.measure(model, data, q))
        plant = None if self.plant is None else self.plant.measures()
        return step_record(
            step, self.t, error, penetration, position_errors, orientation_errors, violation,
            errors, self._names, plant, math.inf if distance is None else distance.minimum_distance,
            "" if distance is None else distance.closest_pair)

    def _row_labels(self) -> tuple[str, ...]:
        """:func:`row_labels` of the current constraints, recomputed when the set changes."""
        key = tuple(map(id, self.constraints))
        if key != self._labels_key:
            self._labels_key, self._labels = key, row_labels(self.constraints)
            self._names = constraint_names(self.constraints)
        return self._labels

    def _measured_kinematics(self, q: np.ndarray, constraints: Sequence[Constraint],
                             frames: Sequence[int],
                             ) -> tuple[pin.Model, pin.Data, Sequence[Constraint]]:
        """The model, data and ``constraints`` (on ``frames``) the measures at the true
        configuration ``q`` take: the loop's own, or with a calibration error the true
        model's and each constraint moved to where the real link met it
        (:meth:`TrueKinematics.constraints`, registered at ``q`` when first met)."""
        true = self.true_kinematics
        if true is None:
            return self.model, self.data, constraints
        return true.model, true.data, true.constraints(constraints, frames, q)
