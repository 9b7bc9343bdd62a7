"""The page's one robot over ROS 2 (``teleop web --plant ros2``, docs/ros2.md): one
:class:`~teleop.plants.ros2.Ros2Plant` for the whole session, so one publisher on the
robot's controller whatever the operator rebuilds.

A controller switch or a new rate builds the main robot's loop again: each new loop gets
the same plant (its period follows the loop's, :meth:`Ros2Plant.set_period`), never a
second writer on the command topic. The main robot is the only loop on it: a ghost would
command the same robot, so :class:`Ros2Robot` refuses one (:meth:`refuse_ghost`). The
session starts where the robot is (:meth:`state`: the first joint state), and the status
says why the robot stopped (:meth:`stopped`: the watchdog's stale state, a refused joint
state, a non-finite command). The robot's clock paces the control thread (:meth:`pace`,
outside the app's lock)."""

from __future__ import annotations

import numpy as np

from teleop.plants import PlantChoice
from teleop.robots import Robot


class Ros2Robot:
    """The session's one :class:`~teleop.plants.ros2.Ros2Plant` (module docstring).

    Parameters
    ----------
    robot : the robot model (its joint names are the robot's on the wire).
    choice : the session's plant choice (kind ``ros2``, its topics and domain).
    """

    def __init__(self, robot: Robot, choice: PlantChoice) -> None:
        if choice.kind != "ros2":
            raise ValueError(f"Ros2Robot needs the ros2 plant, got {choice.kind}")
        self.robot = robot
        self.choice = choice
        self._plant = None

    def plant(self, dt: float):
        """The session's plant at period ``dt``: made (joined to the wire) the first time,
        the same one after that, its period set to ``dt``."""
        if self._plant is None:
            self._plant = self.choice.make(self.robot, dt)
        else:
            self._plant.set_period(dt)
        return self._plant

    def state(self, dt: float) -> np.ndarray:
        """The robot's configuration now: the first joint state received (``ValueError``
        naming the silent topic or a joint it does not carry)."""
        return self.plant(dt).wait_for_state()

    def pace(self) -> None:
        """The robot's next state awaited (:meth:`Ros2Plant.pace`): the control thread
        calls it before each tick, outside the app's lock, so a drag does not wait while
        the tick waits for the robot (nothing before the plant is made)."""
        if self._plant is not None:
            self._plant.pace()

    def stopped(self) -> str:
        """Why the robot is stopped, in words (empty while it is commanded)."""
        if self._plant is None:
            return ""
        reason = self._plant.measures().stopped
        return f"the ROS 2 robot is stopped ({reason})" if reason else ""

    @staticmethod
    def refuse_ghost(spec: str | None) -> None:
        """``ValueError`` for a ghost: the page drives one robot over ROS 2."""
        if spec:
            raise ValueError(f"no ghost ({spec}) on the ros2 plant: the page drives one robot "
                             "over ROS 2, a second loop would command it too")

    def close(self) -> None:
        """Zeros published and the node closed (the plant's own :meth:`close`)."""
        if self._plant is not None:
            self._plant.close()
