"""Home through the constraints (docs/design.md section 20.3): with constraints placed,
"Home" plans a joint path to the home configuration whose steps keep the constraint rows
(:func:`teleop.loop.homing.plan_home_path`), and the targets follow its EE poses in full
pose (the loops' task mode for the while), paced at 0.8 of the loop's caps; then every
target rests on its home pose and the session's task mode returns. When home cannot be
reached through the constraints, the path goes as far as it can and :attr:`home_words`
says why. Any target the operator sets meanwhile ends it where it is.
"""

from __future__ import annotations

import copy
import threading
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from teleop.loop import LoopConfig, TeleopLoop
from teleop.loop.homing import HOME_TOLERANCE, path_poses, path_times, plan_home_path
from teleop.robots import Robot


#: After its last sample, the way home ends when the main robot is there (within
#: :data:`~teleop.loop.homing.HOME_TOLERANCE` of it), or this many seconds later (s)
HOME_SETTLE = 2.0


@dataclass(frozen=True)
class HomeRun:
    """A way home being followed: each sample's EE poses, when the targets reach it (s
    from ``start``, the app's time), and why it does not end at home (empty when it
    does)."""

    poses: list[list[pin.SE3]]
    times: np.ndarray
    start: float
    words: str
    end: np.ndarray  # the last configuration of the path


class Homing:
    """Home through the constraints for :class:`web.app.TeleopApp` (its state:
    :attr:`homing`, the run followed now or None; :attr:`home_words`, why the last one
    could not reach home, empty when it could)."""

    robot: Robot
    config: LoopConfig
    entries: dict
    inputs: list
    specs: dict[str, str]
    loops: dict[str, TeleopLoop]
    homing: HomeRun | None
    home_words: str
    _lock: threading.RLock

    def _start_homing(self) -> str:
        """Plan the way home from where the main robot is and follow it (caller holds
        no lock: the plan, milliseconds to tens of them, runs outside it on copies of the
        constraints while the robot holds its targets); the words of :attr:`home_words`."""
        model = self.robot.model
        with self._lock:
            loop = self.loops["main"]
            q = loop.q.copy()
            constraints = [copy.copy(constraint) for constraint in loop.constraints]
            frames = list(loop.controller.constraint_frames)
            caps = self.config.max_linear_speed, self.config.max_angular_speed
        path = plan_home_path(model, q, self.robot.q_home, constraints, frames)
        poses = path_poses(model, path.configurations, self.robot.ee_frame_ids)
        times = path_times(model, path.configurations, poses, *caps)
        with self._lock:
            self.homing = HomeRun(poses, times, self.now, path.words, path.configurations[-1])
            self.home_words = path.words
            self._apply_task_modes()  # the loops in full pose while it runs
        return path.words

    def _follow_homing(self) -> None:
        """The targets on the way home at the app's time (caller holds the lock, once a
        period before the loops advance; the gizmos stay, whose next motion moves the
        targets from there); once the main robot is at its last sample (or
        :data:`HOME_SETTLE` after it is due there), the targets stay there and the
        session's task mode returns."""
        run = self.homing
        if run is None:
            return
        elapsed = self.now - run.start
        index = int(np.searchsorted(run.times, elapsed, side="right")) - 1
        for ee, pose in enumerate(run.poses[min(index, len(run.poses) - 1)]):
            self.inputs[ee].target = pose.copy()  # the gizmo stays: its next move is relative
            self.recorder.target(ee, pose)
        arrived = np.max(np.abs(self.loops["main"].q - run.end)) < HOME_TOLERANCE
        if elapsed >= run.times[-1] and (arrived or elapsed >= run.times[-1] + HOME_SETTLE):
            self._end_homing()

    def _end_homing(self) -> None:
        """The run over (caller holds the lock): the targets stay where they are, the
        loops return to the session's task mode."""
        if self.homing is None:
            return
        self.homing = None
        self._apply_task_modes()

    def homing_words(self) -> str:
        """What "Home" is doing or why it stopped short, in words; ``""`` otherwise."""
        with self._lock:
            run = self.homing
            if run is not None:
                share = min(1.0, (self.now - run.start) / max(run.times[-1], 1e-9))
                return (f"going home through the constraints ({100 * share:.0f} %)"
                        + (f"; it will stop short: {run.words}" if run.words else ""))
            return f"home not reached: {self.home_words}" if self.home_words else ""
