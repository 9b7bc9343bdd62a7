"""The operator's input devices (docs/design.md section 19): each drives one end
effector's target through the same clutch, motion scale and view mapping as the gizmo.

The control tick, before the robots' step, takes each source's newest sample
(:meth:`InputDevices.apply`): a pose moves the target by the device's motion since
its previous sample, a twist integrates over the period (:mod:`teleop.inputs.mapping`),
both in the frame of the operator's view (:meth:`InputDevices.set_view`). After the step
(:meth:`InputDevices.commanded`) each sample a command used gets its latency, and
each source that renders feedback the wrench to render (:mod:`teleop.inputs.feedback`).

The **watchdog**: a streaming source silent longer than :attr:`input_timeout` is
released: its target is put where the robot's EE is and the loops' filtered targets with
it, so the next command asks no motion (the robot stops), and the status says why. The
next sample starts a new stream, from where the target is (no jump).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from constraints.collision import CollisionRows
from constraints.validation import as_number
from teleop.inputs import (DEFAULT_VIEW, FeedbackGains, FeedbackState, InputSample, InputSource,
                           device_pose, feedback_wrench, followed_pose, integrated_twist,
                           view_rotation)
from teleop.limits import MAX_INPUT_TIMEOUT_S, MIN_INPUT_TIMEOUT_S
from teleop.loop import TeleopLoop

from .console import EEInput
from .limits import HISTORY_RATE, HISTORY_SECONDS, MAX_TARGET_DISTANCE
from .recording import SessionRecording

#: a streaming source silent longer than this is released (s)
DEFAULT_INPUT_TIMEOUT = 0.1
#: the watchdog's timeout is within these (s)
INPUT_TIMEOUT_RANGE = (MIN_INPUT_TIMEOUT_S, MAX_INPUT_TIMEOUT_S)
#: a device's moving target is written to a recording at most once per this many ticks
#: (its last move at most this many ticks late)
RECORD_TARGET_EVERY = 10
#: a recording gets each source's statistics this often (s)
RECORD_INPUT_EVERY = 1.0
#: absolute orientation follows once the device and the tool agree within this (rad)
ALIGNMENT = np.radians(10.0)
#: a rate command keeps its target within this of the EE (m, rad): a few periods at the
#: speed caps, so a device held against a limit does not wind the target up
RATE_LEAD, RATE_TURN_LEAD = 0.01, 0.05
#: the status's latency percentiles are over the last this many commands
STATUS_LATENCIES = 4096


@dataclass
class DeviceBinding:
    """A source driving EE ``source.ee``, and what it did last."""

    source: InputSource
    state: FeedbackState = FeedbackState.HELD
    reason: str = "waiting for its first command"
    previous: pin.SE3 | None = None  # the device's previous pose (pose sources)
    twist: np.ndarray = field(default_factory=lambda: np.zeros(6))  # rate command held
    used: InputSample | None = None  # the sample this tick's command uses
    wrench: np.ndarray = field(default_factory=lambda: np.zeros(6))  # device frame
    #: the feedback force (device frame, N) at the history rate: time, fx, fy, fz
    history: list[tuple[float, float, float, float]] = field(default_factory=list)
    recorded_applied: int = 0  # the applied count at the last recording of statistics
    unrecorded: bool = False  # its target moved since it was last written to a recording
    recorded_tick: int = 0  # the tick it was last written at
    aligned: bool = False  # absolute orientation: the device agreed with its tool
    rate_control: bool = False  # its last sample was a twist


class InputDevices:
    """The input devices of :class:`web.app.TeleopApp`, a component that owns them: the
    bound sources (iterating over it gives each :class:`DeviceBinding`), the operator's
    :attr:`view_rotation`, whether orientation is :attr:`absolute_orientation`, the
    watchdog's :attr:`input_timeout` and the :attr:`feedback_gains`. Its operator's
    actions take the session's lock; the control tick calls :meth:`apply` and
    :meth:`commanded` holding it, with the targets, the loops, the clutch and the motion
    scale.

    Parameters
    ----------
    recorder : the session's recording (the devices' targets and statistics go there).
    lock : the session's lock.
    ee_count : how many end effectors the robot has (a source drives one of them).
    """

    def __init__(self, recorder: SessionRecording, lock: threading.RLock,
                 ee_count: int) -> None:
        self._recorder = recorder
        self._lock = lock
        self._ee_count = ee_count
        self._bindings: list[DeviceBinding] = []
        self.view_rotation = DEFAULT_VIEW.copy()
        self.absolute_orientation = False
        self.input_timeout = DEFAULT_INPUT_TIMEOUT
        self.feedback_gains = FeedbackGains()
        self._next_input_record = 0.0

    def __iter__(self) -> Iterator[DeviceBinding]:
        return iter(self._bindings)

    def __len__(self) -> int:
        return len(self._bindings)

    def __getitem__(self, index: int) -> DeviceBinding:
        return self._bindings[index]

    def attach(self, source: InputSource) -> None:
        """``source`` drives EE ``source.ee`` from the next tick (one source per EE); it
        is started here, and closed by :meth:`close`."""
        with self._lock:
            if not 0 <= source.ee < self._ee_count:
                raise ValueError(f"{source.name}: no end effector {source.ee} (this robot "
                                 f"has {self._ee_count})")
            taken = [d.source.name for d in self._bindings if d.source.ee == source.ee]
            if taken:
                raise ValueError(f"{source.name}: EE {source.ee} is already driven by "
                                 f"{taken[0]}")
            self._bindings.append(DeviceBinding(source))
        source.start()

    def close(self) -> None:
        """Every source unbound and closed (outside the lock: a source's thread may be
        waiting for it)."""
        with self._lock:
            bindings, self._bindings = self._bindings, []
        for binding in bindings:
            binding.source.close()

    def set_input_timeout(self, seconds: float) -> None:
        """The watchdog's timeout (s), within :data:`INPUT_TIMEOUT_RANGE`: a streaming
        source silent longer is released."""
        seconds = as_number(seconds, "input timeout")
        low, high = INPUT_TIMEOUT_RANGE
        if not low <= seconds <= high:
            raise ValueError(f"input timeout must be between {1e3 * low:g} and "
                             f"{1e3 * high:g} ms, got {1e3 * seconds:g} ms")
        with self._lock:
            self.input_timeout = seconds

    def set_view(self, camera_wxyz) -> None:
        """The operator's view: the browser camera's orientation (viser's ``wxyz``); the
        devices' motion is mapped into it from now on (no target jumps)."""
        rotation = view_rotation(camera_wxyz)
        if not np.all(np.isfinite(rotation)):
            raise ValueError("the camera orientation must be finite")
        with self._lock:
            if not np.allclose(rotation, self.view_rotation, atol=1e-9):
                self._unalign()
            self.view_rotation = rotation

    def set_orientation_mode(self, absolute: bool) -> None:
        """Orientation relative (through the clutch: the device's rotation since it was
        last coupled) or absolute with respect to the view."""
        if not isinstance(absolute, (bool, np.bool_)):
            raise ValueError(f"absolute orientation is True or False, got {absolute!r}")
        with self._lock:
            self.absolute_orientation = bool(absolute)
            self._unalign()

    def _unalign(self) -> None:
        """In absolute orientation, every device must agree with its tool again before
        it moves it."""
        for device in self._bindings:
            device.aligned = False

    # -- the control tick -----------------------------------------------------------------

    def apply(self, dt: float, inputs: list[EEInput], loops: dict[str, TeleopLoop],
              clutch: bool, motion_scale: float) -> None:
        """Each source's newest sample onto its EE's target (of ``inputs``), through the
        ``clutch`` and the ``motion_scale``; a silent source released, every one of the
        ``loops`` holding its EE."""
        now = time.perf_counter()
        for device in self._bindings:
            source = device.source
            sample = device.used = source.take()
            if sample is None:
                silent = (source.last_arrival is not None
                          and now - source.last_arrival > self.input_timeout)
                if source.watchdog and device.state != FeedbackState.HELD and silent:
                    self._release(device, 1e3 * (now - source.last_arrival), inputs, loops)
                elif device.state == FeedbackState.FOLLOWING and not clutch \
                        and np.any(device.twist):
                    self._move_target(device, integrated_twist(
                        inputs[source.ee].target, device.twist, self.view_rotation,
                        motion_scale, dt), inputs, loops["main"])
                continue
            if device.state == FeedbackState.HELD:  # a new stream: from where the target is
                device.previous = None
            coupled = not clutch and not sample.clutched
            if not coupled:
                device.aligned = False
            device.state = FeedbackState.FOLLOWING if coupled else FeedbackState.CLUTCHED
            device.reason = "following" if coupled else "clutched: the device moves alone"
            hand = inputs[source.ee]
            device.rate_control = sample.kind == "twist"
            if sample.kind == "pose":
                pose, previous = device_pose(sample.values), device.previous
                device.previous = pose
                if coupled and self.absolute_orientation and not device.aligned:
                    self._align(device, hand.target, pose)
                elif coupled and previous is not None:
                    self._move_target(device, followed_pose(
                        hand.target, previous, pose, self.view_rotation, motion_scale,
                        self.absolute_orientation), inputs, loops["main"])
            else:
                device.twist = np.array(sample.values[:6]) if coupled else np.zeros(6)
                if coupled:
                    self._move_target(device, integrated_twist(
                        hand.target, device.twist, self.view_rotation, motion_scale, dt),
                        inputs, loops["main"])

    def _align(self, device: DeviceBinding, target: pin.SE3, pose: pin.SE3) -> None:
        """Absolute orientation: the device follows only once its orientation in the view
        agrees with the tool's within :data:`ALIGNMENT` (the dVRK's alignment); until
        then it is held clutched, the status saying how far apart they are."""
        apart = float(np.linalg.norm(pin.log3(self.view_rotation @ pose.rotation
                                              @ target.rotation.T)))
        device.aligned = apart <= ALIGNMENT
        if not device.aligned:
            device.state = FeedbackState.CLUTCHED
            device.reason = (f"align the device with the tool: {np.degrees(apart):.0f} deg "
                             f"apart (absolute orientation follows within "
                             f"{np.degrees(ALIGNMENT):.0f} deg)")

    def _move_target(self, device: DeviceBinding, target: pin.SE3, inputs: list[EEInput],
                     main: TeleopLoop) -> None:
        """EE ``device.source.ee``'s target (of ``inputs``) from its device, the ``main`` robot's EE
        there; one farther than
        :data:`MAX_TARGET_DISTANCE` from the EE is refused (counted ``refused``); a rate
        command does not take the target farther than :data:`RATE_LEAD` (or turned more
        than :data:`RATE_TURN_LEAD`) from the EE than it is: held against a constraint, a
        limit or the speed caps, it does not wind up (counted ``held_back``)."""
        ee = device.source.ee
        now = main.ee_placements()[ee]
        ahead = float(np.linalg.norm(target.translation - now.translation))
        if not ahead <= MAX_TARGET_DISTANCE:
            device.source.count("refused")
            return
        if device.rate_control:
            current = inputs[ee].target
            was = float(np.linalg.norm(current.translation - now.translation))
            turned = float(np.linalg.norm(pin.log3(target.rotation @ now.rotation.T)))
            turned_was = float(np.linalg.norm(pin.log3(current.rotation @ now.rotation.T)))
            if (ahead > RATE_LEAD and ahead > was) or (turned > RATE_TURN_LEAD
                                                       and turned > turned_was):
                device.source.count("held_back")
                return
        inputs[ee].target = target
        device.unrecorded = True

    def _release(self, device: DeviceBinding, silent_ms: float, inputs: list[EEInput],
                 loops: dict[str, TeleopLoop]) -> None:
        """The watchdog: the source is released, its target holds where the robot's EE is
        and every loop's filtered target with it ."""
        ee = device.source.ee
        device.state = FeedbackState.HELD
        device.reason = (f"silent for {silent_ms:.0f} ms (timeout "
                         f"{1e3 * self.input_timeout:g} ms): released, the robot holds")
        device.twist = np.zeros(6)
        device.source.count("releases")
        release = getattr(device.source, "release", None)
        if release is not None:
            release()
        pose = loops["main"].ee_placements()[ee]
        inputs[ee].target = pose.copy()
        self._recorder.target(ee, pose)
        for loop in loops.values():
            loop.hold(ee, pose)

    def commanded(self, history: bool, ticks: int, inputs: list[EEInput], main: TeleopLoop,
                  rows: CollisionRows | None, detection_distance: float) -> None:
        """After the robots' step at tick ``ticks``: each used sample's latency, each
        feedback (``history``: a history tick, the feedback force is kept for the plot),
        from the ``main`` robot, its targets (``inputs``) and its collision ``rows``
        (their detection distance)."""
        command_time = time.perf_counter()
        loop = main
        placements = None
        for device in self._bindings:
            if device.used is not None:
                device.source.used(device.used, command_time)
            if (device.unrecorded and self._recorder.active
                    and ticks - device.recorded_tick >= RECORD_TARGET_EVERY):
                self._recorder.target(device.source.ee, inputs[device.source.ee].target)
                device.unrecorded, device.recorded_tick = False, ticks
            if not device.source.renders_feedback and not history:
                continue
            if placements is None:
                placements = loop.ee_placements()
            measures = None if loop.plant is None else loop.plant.measures()
            port_forces = getattr(measures, "port_forces", [])  # a plant's own measures
            sensed = getattr(measures, "tool_wrenches", np.zeros((0, 6)))
            tool = sensed[device.source.ee] if device.source.ee < len(sensed) else None
            ee = placements[device.source.ee]  # no spring while the device moves alone
            device.wrench = feedback_wrench(
                ee, inputs[device.source.ee].target
                if device.state == FeedbackState.FOLLOWING else ee,
                port_forces, rows,
                detection_distance, self.view_rotation, self.feedback_gains,
                tool)
            device.source.set_feedback(device.wrench, device.state, loop.plant is not None)
            if history:
                device.history.append((loop.t, *device.wrench[:3]))
                del device.history[:-int(HISTORY_SECONDS * HISTORY_RATE)]
        if self._recorder.active and loop.t >= self._next_input_record:
            self._record_inputs()
            self._next_input_record = loop.t + RECORD_INPUT_EVERY

    def _record_inputs(self) -> None:
        """Each source's counts and its latencies since the last such line, to the
        recording."""
        for device in self._bindings:
            source = device.source
            counts = source.counts_now()
            fresh = min(counts.get("applied", 0) - device.recorded_applied, 4096)
            device.recorded_applied = counts.get("applied", 0)
            latencies = source.latencies.values()[-fresh:] if fresh else np.zeros(0)
            self._recorder.input(source.name, source.ee,
                                {key: int(value) for key, value in counts.items()},
                                latencies)

    def snapshot(self) -> list[dict]:
        """What the status and the plot show of each device."""
        return [{"name": d.source.name, "ee": d.source.ee, "state": d.state,
                 "reason": d.reason, "wrench": d.wrench.copy(),
                 "history": list(d.history), "source": d.source}
                for d in self._bindings]
