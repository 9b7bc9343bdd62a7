"""The robot under the session's loops: the ideal integrator or the MuJoCo physics plant
(docs/design.md section 17), one plant per loop, and what the view reads of it: the wall's
force on the instrument at each port (docs/design.md section 5.3)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from constraints import Constraint
from teleop.loop import TeleopLoop
from teleop.plants import PlantChoice
from teleop.plants.walls import wall_of
from teleop.robots import Robot

from .ros2_robot import Ros2Robot


@dataclass(frozen=True)
class PortReading:
    """The wall at one port, as the view draws it (world frame).

    Attributes
    ----------
    id : the entry id of the constraint that puts the wall there.
    point : where the instrument crosses the wall (the constraint's ``port``, m).
    force : the wall's force on the instrument there (N).
    displacement : the tissue's lateral displacement (m).
    """

    id: str
    point: np.ndarray
    force: np.ndarray
    displacement: float

    @property
    def magnitude(self) -> float:
        """``|force|`` (N)."""
        return float(np.linalg.norm(self.force))


def apply_wall(constraint: Constraint, stiffness: float | None) -> None:
    """The session's wall ``stiffness`` (N/m; None: the port's own) on a constraint that
    puts a wall into the scene (:func:`teleop.plants.walls.wall_of`)."""
    wall = wall_of(constraint)
    if wall is not None and stiffness is not None:
        wall.set_stiffness(constraint, stiffness)


def port_readings(loop: TeleopLoop, placements: list[pin.SE3], ids: dict[int, str],
                  model: pin.Model) -> list[PortReading]:
    """The wall at each port of ``loop``'s plant over its last period (``placements``
    every frame's at ``loop.q``; ``ids`` the placed constraints' ids by ``id()``, a port
    without one named by its link). Empty without a physics plant, or until the plant has
    stepped with the current constraints."""
    if loop.plant is None:
        return []
    walls = [(c, wall) for c in loop.constraints if (wall := wall_of(c)) is not None]
    measures = loop.plant.measures()
    if len(walls) != len(measures.port_forces):  # constraints changed since the step
        return []
    readings = []
    for (port, wall), force, displacement in zip(walls, measures.port_forces,
                                                 measures.port_displacements):
        link = placements[model.getFrameId(port.link)]
        point, _ = wall.port(port, link.rotation, link.translation)
        readings.append(PortReading(ids.get(id(port), port.link), point,
                                    np.array(force, dtype=float), float(displacement)))
    return readings


def continue_plant(old: TeleopLoop | None, new: TeleopLoop) -> None:
    """``new`` takes over from ``old`` (the same robot, or None for a new one) at
    ``new.q``: at the same period it drives the same simulated robot, whose physics
    goes on (a controller switch does not stop a moving arm); else its own plant
    rests at ``new.q``."""
    if new.plant is None:
        return
    if old is not None and old.plant is not None and old.plant.dt == new.plant.dt:
        new.plant = old.plant
    else:
        new.plant.reset(new.q)


def session_plant(choice: PlantChoice, robot: Robot, ros2: Ros2Robot | None, dt: float):
    """A plant for a loop of period ``dt``: the session's one robot over ROS 2 (``ros2``),
    else a fresh one of the session's ``choice`` (None: the ideal integrator)."""
    if ros2 is not None:
        return ros2.plant(dt)
    return choice.make(robot, dt)
