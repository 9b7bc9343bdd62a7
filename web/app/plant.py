"""The robot under the session's loops: the ideal integrator or the MuJoCo physics plant
(docs/design.md section 17), one plant per loop, and what the view reads of it: the wall's
force on the instrument at each port (docs/design.md section 5.3)."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.validation import as_number
from teleop.loop import TeleopLoop
from teleop.plants import MujocoPlant, PlantSettings
from teleop.robots import Robot

from .limits import MAX_WALL_STIFFNESS

#: the plants a session may run on: the ideal integrator, the MuJoCo physics
PLANTS = ("kinematic", "mujoco")


@dataclass(frozen=True)
class PlantChoice:
    """What every loop of the session runs on.

    Attributes
    ----------
    kind : ``"kinematic"`` (``q += qd dt``, no plant) or ``"mujoco"`` (:class:`MujocoPlant`).
    settings : the physics plant's body and servos (payload, friction...).
    wall_stiffness : the abdominal wall's lateral stiffness (N/m) at every port of the
        session, placed or loaded; None: each port's own (its constraint's default, 1 N/mm).
    """

    kind: str = "kinematic"
    settings: PlantSettings = field(default_factory=PlantSettings)
    wall_stiffness: float | None = None

    def __post_init__(self) -> None:
        """``ValueError`` naming the field for a kind not in :data:`PLANTS`, settings that
        are not :class:`PlantSettings`, a stiffness not in (0, MAX_WALL_STIFFNESS]."""
        if self.kind not in PLANTS:
            raise ValueError(f"plant must be one of {', '.join(PLANTS)}, got {self.kind!r}")
        if not isinstance(self.settings, PlantSettings):
            raise ValueError(f"plant settings must be PlantSettings, got "
                             f"{type(self.settings).__name__}")
        if self.wall_stiffness is not None:
            as_number(self.wall_stiffness, "wall_stiffness", positive=True,
                      maximum=MAX_WALL_STIFFNESS)

    @property
    def physical(self) -> bool:
        """Whether the loops run on a physics plant (ports, forces, torques)."""
        return self.kind != "kinematic"

    def make(self, robot: Robot, dt: float) -> MujocoPlant | None:
        """A new plant for one loop at period ``dt`` (None: the ideal integrator)."""
        return MujocoPlant(robot, dt, self.settings) if self.physical else None

    def describe(self) -> str:
        """One line for the operator."""
        if not self.physical:
            return "kinematic plant (q += qd dt)"
        wall = ("each port's own wall" if self.wall_stiffness is None
                else f"wall {self.wall_stiffness / 1e3:g} N/mm")
        return f"{self.settings.describe()}, {wall}"


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


class Plants:
    """The plants of :class:`web.app.TeleopApp`'s loops (its state: ``plant``)."""

    robot: Robot
    plant: PlantChoice
    entries: dict
    loops: dict[str, TeleopLoop]
    _lock: threading.RLock

    def _apply_wall(self, constraint: Constraint) -> None:
        """The session's wall stiffness on a constraint that puts a wall into the scene
        (``has_wall``), when the session sets one."""
        if constraint.has_wall and self.plant.wall_stiffness is not None:
            constraint.tissue_stiffness = self.plant.wall_stiffness

    def _continue_plant(self, old: TeleopLoop | None, new: TeleopLoop) -> None:
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

    def _ports(self, loop: TeleopLoop, placements: list[pin.SE3]) -> list[PortReading]:
        """The wall at each port of ``loop``'s plant over its last period (caller holds
        the lock; ``placements`` every frame's at ``loop.q``). Empty without a physics
        plant, or until the plant has stepped with the current constraints."""
        if loop.plant is None:
            return []
        ids = {id(entry.constraint): entry.id for entry in self.entries.values()}
        walls = [c for c in loop.constraints if c.has_wall]
        measures = loop.plant.measures()
        if len(walls) != len(measures.port_forces):  # constraints changed since the step
            return []
        readings = []
        for wall, force, displacement in zip(walls, measures.port_forces,
                                             measures.port_displacements):
            link = placements[self.robot.model.getFrameId(wall.link)]
            point, _ = wall.port(link.rotation, link.translation)
            readings.append(PortReading(ids.get(id(wall), wall.link), point,
                                        np.array(force, dtype=float), float(displacement)))
        return readings
