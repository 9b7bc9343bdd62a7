"""Home through the constraints (docs/design.md section 20.3): with constraints placed,
"Home" plans a joint path to the home configuration whose steps keep the constraint rows
(:func:`teleop.loop.homing.plan_home_path`), and the targets follow its EE poses in full
pose (the loops' task mode for the while), paced at 0.8 of the loop's caps; then every
target rests on its home pose and the session's task mode returns. When home cannot be
reached through the constraints, the path goes as far as it can and :attr:`WayHome.words`
says why. Any target the operator sets meanwhile ends it where it is.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from constraints import Constraint
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


class WayHome:
    """Home through the constraints, a component of :class:`web.app.TeleopApp`: it owns
    the run followed now (:attr:`run`, or None) and why the last one could not reach home
    (:attr:`words`, empty when it could). The app calls it under its lock, but
    :meth:`plan`, which runs outside it on copies of the constraints.

    Parameters
    ----------
    robot : the robot (its model, home configuration and EE frames).
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.run: HomeRun | None = None
        self.words = ""

    @property
    def active(self) -> bool:
        """Whether a way home is being followed."""
        return self.run is not None

    def plan(self, q: np.ndarray, constraints: list[Constraint], frames: list[int],
             caps: tuple[float, float]) -> HomeRun:
        """The way home from ``q`` whose steps keep the ``constraints`` (at their
        ``frames``), its samples timed at the speed ``caps`` (linear, angular) from 0 (no
        lock needed: it reads only its arguments and the robot)."""
        model = self.robot.model
        path = plan_home_path(model, q, self.robot.q_home, constraints, frames)
        poses = path_poses(model, path.configurations, self.robot.ee_frame_ids)
        times = path_times(model, path.configurations, poses, *caps)
        return HomeRun(poses, times, 0.0, path.words, path.configurations[-1])

    def follow(self, run: HomeRun, now: float) -> str:
        """Follow a way :meth:`plan` made, from app time ``now``; the words of
        :attr:`words`."""
        self.run = replace(run, start=now)
        self.words = run.words
        return run.words

    def targets(self, now: float, q: np.ndarray) -> tuple[list[pin.SE3], bool]:
        """The targets on the way home at app time ``now`` with the main robot at ``q``,
        and whether the run is over: the main robot is at its last sample (or
        :data:`HOME_SETTLE` after it is due there). Called once a period while
        :attr:`active`; the run ends (:meth:`end`) when the caller is done with it."""
        run = self.run
        assert run is not None
        elapsed = now - run.start
        index = int(np.searchsorted(run.times, elapsed, side="right")) - 1
        poses = [pose.copy() for pose in run.poses[min(index, len(run.poses) - 1)]]
        arrived = np.max(np.abs(q - run.end)) < HOME_TOLERANCE
        over = elapsed >= run.times[-1] and (arrived or elapsed >= run.times[-1] + HOME_SETTLE)
        return poses, bool(over)

    def end(self) -> bool:
        """The run over, the targets staying where they are; whether one was followed."""
        followed, self.run = self.run is not None, None
        return followed

    def forget(self) -> None:
        """The operator moved a target: any run ends where it is, and why the last one
        stopped short no longer applies."""
        self.words = ""

    def words_at(self, now: float) -> str:
        """What "Home" is doing at app time ``now`` or why it stopped short, in words;
        ``""`` otherwise."""
        run = self.run
        if run is not None:
            share = min(1.0, (now - run.start) / max(run.times[-1], 1e-9))
            return (f"going home through the constraints ({100 * share:.0f} %)"
                    + (f"; it will stop short: {run.words}" if run.words else ""))
        return f"home not reached: {self.words}" if self.words else ""
