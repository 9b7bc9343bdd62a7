"""Recording the session: the operator's targets and constraint events to a session file
(:mod:`teleop.experiments.sessions`), replayable with ``teleop replay``."""

from __future__ import annotations

import threading
from datetime import datetime
from pathlib import Path

from teleop.experiments.sessions import SessionRecorder
from teleop.loop import LoopConfig, TeleopLoop
from teleop.robots import Robot

from ..folders import Folder


class Recording:
    """The recorder of :class:`web.app.TeleopApp` (its state: ``recorder`` and the app
    time it started at)."""

    robot: Robot
    config: LoopConfig
    loops: dict[str, TeleopLoop]
    recordings: Folder
    entries: dict
    inputs: list
    recorder: SessionRecorder | None
    _record_start: float
    _lock: threading.RLock

    @property
    def recording_time(self) -> float:
        """Seconds since the recording started (app time)."""
        return self.now - self._record_start

    def start_recording(self, name: str | None = None) -> Path:
        """Record the session to file ``name`` of the recording folder (default: a new
        name, by date); its path. A name already in the folder is refused: a recording
        never replaces another."""
        with self._lock:
            if self.recorder is not None:
                raise ValueError(f"already recording to {self.recorder.path.name}")
            if name is None:
                name = self.recordings.unused_name(f"session-{datetime.now():%Y%m%d-%H%M%S}")
            path = self.recordings.new(name)
            self.recorder = SessionRecorder(path, self.robot, self.loops["main"].q,
                                            rate_hz=self.config.rate, kp=self.config.kp,
                                            target_time_constant_s=self.config.target_time_constant)
            self._record_start = self.now
            for entry in self.entries.values():
                self.recorder.add(0.0, entry.id, entry.constraint)
            self.recorder.task_modes(0.0, self.loops["main"].task_modes)
            for index in range(len(self.inputs)):
                self._record_target(index)
            return self.recorder.path

    def stop_recording(self) -> Path:
        with self._lock:
            if self.recorder is None:
                raise ValueError("not recording")
            recorder, self.recorder = self.recorder, None
            recorder.close(self.recording_time)
            return recorder.path

    def _record_target(self, ee: int) -> None:
        """Write EE ``ee``'s target to the session when recording (a single-EE robot's
        events name no frame)."""
        if self.recorder is None:
            return
        hand = self.inputs[ee]
        if len(self.inputs) == 1:
            self.recorder.target(self.recording_time, hand.target)
        else:
            self.recorder.target(self.recording_time, hand.target, frame=hand.frame)
