"""Recording the session: the operator's targets and constraint events to a session file
(:mod:`teleop.experiments.sessions`), replayable with ``teleop replay``."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from datetime import datetime
from pathlib import Path

import numpy as np
import pinocchio as pin

from constraints import Constraint
from teleop.experiments.sessions import SessionRecorder
from teleop.loop import LoopConfig
from teleop.robots import Robot

from ..folders import Folder


class SessionRecording:
    """The session's recorder, a component of :class:`web.app.TeleopApp`: it owns the
    open session file (or none) and the app time it started at, and writes each event the
    app hands it while recording (every event method does nothing otherwise). The app
    calls it under its lock.

    Parameters
    ----------
    folder : the folder recordings go to, and no other.
    clock : the app's time (s), read at each event.
    ee_frames : the robot's EE frames (``robot.ee_frames``): the target events of a robot
        with several name their frame, a single EE's name none.
    """

    def __init__(self, folder: Folder, clock: Callable[[], float],
                 ee_frames: Sequence[str]) -> None:
        self.folder = folder
        self._clock = clock
        self._ee_frames = list(ee_frames)
        self._recorder: SessionRecorder | None = None
        self._start = 0.0

    @property
    def active(self) -> bool:
        """Whether a session file is open."""
        return self._recorder is not None

    @property
    def time(self) -> float:
        """Seconds since the recording started (app time)."""
        return self._clock() - self._start

    def start(self, name: str | None, robot: Robot, q: np.ndarray, config: LoopConfig,
              constraints: Iterable[tuple[str, Constraint]], task_modes: tuple[str, ...],
              targets: Sequence[pin.SE3]) -> Path:
        """Open file ``name`` of the folder (default: a new name, by date) and write the
        session's start: the robot at ``q``, the loop's settings, the placed ``constraints``
        (id, constraint), the ``task_modes`` and each EE's target; its path.
        A name already in the folder is refused: a recording never replaces another."""
        if self._recorder is not None:
            raise ValueError(f"already recording to {self._recorder.path.name}")
        if name is None:
            name = self.folder.unused_name(f"session-{datetime.now():%Y%m%d-%H%M%S}")
        path = self.folder.new(name)
        self._recorder = SessionRecorder(path, robot, q, rate_hz=config.rate, kp=config.kp,
                                         target_time_constant_s=config.target_time_constant)
        self._start = self._clock()
        for entry_id, constraint in constraints:
            self._recorder.add(0.0, entry_id, constraint)
        self._recorder.task_modes(0.0, task_modes)
        for ee, pose in enumerate(targets):
            self.target(ee, pose)
        return self._recorder.path

    def stop(self) -> Path:
        """Close the session file; its path."""
        if self._recorder is None:
            raise ValueError("not recording")
        recorder, self._recorder = self._recorder, None
        recorder.close(self.time)
        return recorder.path

    def target(self, ee: int, pose: pin.SE3) -> None:
        """EE ``ee``'s target (a single-EE robot's events name no frame)."""
        if self._recorder is None:
            return
        if len(self._ee_frames) == 1:
            self._recorder.target(self.time, pose)
        else:
            self._recorder.target(self.time, pose, frame=self._ee_frames[ee])

    def add(self, entry_id: str, constraint: Constraint) -> None:
        """A constraint placed."""
        if self._recorder is not None:
            self._recorder.add(self.time, entry_id, constraint)

    def remove(self, entry_id: str) -> None:
        """A constraint removed."""
        if self._recorder is not None:
            self._recorder.remove(self.time, entry_id)

    def move(self, entry_id: str, position: np.ndarray, velocity: np.ndarray) -> None:
        """A constraint's point moving."""
        if self._recorder is not None:
            self._recorder.move(self.time, entry_id, position, velocity)

    def task_modes(self, modes: tuple[str, ...]) -> None:
        """The task modes the loops run in now."""
        if self._recorder is not None:
            self._recorder.task_modes(self.time, modes)

    def input(self, name: str, ee: int, counts: dict[str, int], latencies: np.ndarray) -> None:
        """An input device's counts and latencies."""
        if self._recorder is not None:
            self._recorder.input(self.time, name, ee, counts, latencies)
