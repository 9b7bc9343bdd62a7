"""Force control in the page (docs/design.md section 21.6): a tissue under the tool, the
tool-frame hybrid law on chosen axes towards a setpoint, and the contact force the view
draws (an arrow at the tip) and plots.

A component of :class:`web.app.TeleopApp` (``app.force``), holding its own state:

* :meth:`ForceControl.place_tissue` puts a :class:`~teleop.plants.tissue.TissueSurface`
  (the default organ tissue, 21.1) :data:`TISSUE_GAP` beyond the main robot's tool tip,
  its normal against the tool's z, into every loop's physics plant (each gets a fresh
  MuJoCo plant with the tool's force/torque sensor, at rest where its robot is); only on
  the mujoco plant (the kinematic one has no sensor: refused by name).
* :meth:`ForceControl.set_enabled` wraps every loop's controller in
  :class:`~teleop.loop.force_controlled.ForceControlled` (the loops are rebuilt: the law
  needs the Python path), the law :class:`~teleop.loop.hybrid_force_motion.HybridForceMotion`
  on the first EE, with palpation's settings (21.4) where the rate allows them: the
  force gain :data:`FORCE_GAIN`, lowered to :data:`GAIN_SHARE` of the largest the
  stability check accepts at the rate when that is less (:func:`force_gain_at`), the
  approach at :data:`APPROACH_SPEED`, the 20 Hz force filter (21.3).
* Every period :meth:`ForceControl.feed` hands each wrapped controller its plant's sensor
  reading; on the history ticks :meth:`ForceControl.measure` keeps the main robot's true
  contact force for the plot.
"""

from __future__ import annotations

import collections
import math
import threading
import weakref
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pinocchio as pin

from constraints.validation import as_vector
from teleop.limits import MAX_FORCE_SETPOINT_N
from teleop.loop import TeleopLoop
from teleop.loop.force_controlled import ForceControlled
from teleop.loop.force_stability import GAIN_MARGIN, force_loop_bound
from teleop.loop.hybrid_force_motion import HybridForceMotion
from teleop.loop.tool_wrench import tool_wrench
from teleop.plants import MujocoPlant
from teleop.plants.tissue import TissueSurface
from teleop.robots import Robot

from .limits import HISTORY_RATE, HISTORY_SECONDS
from .plant import PlantChoice

#: how far beyond the tool tip the tissue is placed (m): the law closes the gap
TISSUE_GAP = 2e-3
#: the force gain ``k_f`` ((m/s)/N): palpation's
FORCE_GAIN = 1.0
#: the share of the largest gain the stability check accepts that a rate too slow or too
#: fast for :data:`FORCE_GAIN` gets
GAIN_SHARE = 0.9
#: the periods of delay the law's stability check assumes (the law's default)
DELAY_PERIODS = 2
#: the force loop's speed bound (m/s): the tip meets the tissue at it
APPROACH_SPEED = 0.01
#: the cut-off of the law's filter on the sensed wrench (Hz)
FILTER_CUTOFF = 20.0


class ForceControl:
    """The page's force control (the app's ``force``), a component of
    :class:`web.app.TeleopApp`; every method takes the app's lock.

    Parameters
    ----------
    robot : the session's robot.
    plant : the session's plant choice (a tissue needs the mujoco one).
    lock : the app's lock.
    loops : the robots' loops now, by name (the app replaces them as it rebuilds them).
    make_plant : a fresh plant of the session for a loop of period ``dt`` (None: the ideal
        integrator).
    rebuild : every loop built again, keeping its state (all or nothing: ``ValueError``
        changes nothing); the loops' controllers go through :meth:`wrapped`.
    """

    def __init__(self, robot: Robot, plant: PlantChoice, lock: threading.RLock,
                 loops: Callable[[], dict[str, TeleopLoop]], make_plant: Callable[[float], Any],
                 rebuild: Callable[[], None]) -> None:
        self._robot = robot
        self._plant_choice = plant
        self._lock = lock
        self._loops = loops
        self._make_plant = make_plant
        self._rebuild = rebuild
        #: the tissue placed (None: none)
        self.tissue: TissueSurface | None = None
        self.enabled = False
        #: the force to exert along each tool axis (N), and which axes are force-controlled
        self.setpoint = np.array([0.0, 0.0, 1.0])
        self.axes: tuple[bool, bool, bool] = (False, False, True)
        #: the main robot's true contact force at the history ticks: (t, fx, fy, fz) world
        self.history: collections.deque = collections.deque(
            maxlen=int(HISTORY_SECONDS * HISTORY_RATE))
        #: the wrapped controllers this component made (the loops' while force control is on)
        self._wrappers: weakref.WeakSet[ForceControlled] = weakref.WeakSet()

    # -- the operator's actions -----------------------------------------------------------

    def place_tissue(self) -> None:
        """The tissue :data:`TISSUE_GAP` beyond the main robot's tool tip, against its z,
        in every loop's plant (a fresh plant with the sensor, at rest where its robot is)."""
        self.check_tissue()
        with self._lock:
            loops = self._loops()
            tip = loops["main"].ee_placements()[0]
            self.tissue = TissueSurface(tip.translation + TISSUE_GAP * tip.rotation[:, 2],
                                        -tip.rotation[:, 2])
            for loop in loops.values():
                loop.plant = self.plant(loop.config.dt)
                loop.plant.reset(loop.q)
            self.history.clear()

    def check_tissue(self) -> None:
        """``ValueError`` unless the session's plant can carry a tissue (the mujoco one)."""
        plant = self._plant_choice
        if not plant.physical:
            raise ValueError(f"a tissue needs the mujoco plant (teleop web --plant mujoco): "
                             f"the {plant.kind} plant has no body to press it nor a "
                             f"force/torque sensor")

    def setup(self) -> dict | None:
        """The tissue and the law's settings as a scene's ``"force"`` (None: no tissue;
        :mod:`web.scene`)."""
        with self._lock:
            if self.tissue is None:
                return None
            return {"tissue": self.tissue.to_dict(),
                    "setpoint": [float(x) for x in self.setpoint], "axes": list(self.axes)}

    def take_setup(self, tissue: TissueSurface | None, setpoint: np.ndarray,
                   axes: tuple[bool, bool, bool]) -> tuple:
        """A scene's tissue and settings, before its loops are built (their plants take the
        tissue); without a tissue force control turns off. Returns what it replaced, for
        :meth:`restore_setup` should the loops not build (caller holds the lock and has
        checked the plant with :meth:`check_tissue`)."""
        previous = (self.tissue, self.setpoint, self.axes, self.enabled)
        self.tissue = tissue
        self.setpoint, self.axes = np.array(setpoint, dtype=float), axes
        self.enabled = self.enabled and tissue is not None
        return previous

    def restore_setup(self, previous: tuple) -> None:
        """The tissue and settings :meth:`take_setup` replaced (caller holds the lock)."""
        self.tissue, self.setpoint, self.axes, self.enabled = previous

    def set_enabled(self, enabled: bool) -> None:
        """Force control on (every loop's controller through the law) or off; on needs a
        tissue (its sensor). The loops are rebuilt, keeping their state."""
        if not isinstance(enabled, (bool, np.bool_)):
            raise ValueError(f"force control is True or False, got {enabled!r}")
        if enabled and self.tissue is None:
            raise ValueError("place the tissue first: force control reads the tool's "
                             "force/torque sensor, which comes with it")
        with self._lock:
            previous, self.enabled = self.enabled, bool(enabled)
        try:
            self._rebuild()  # new loops, state kept
        except ValueError:
            with self._lock:
                self.enabled = previous
            raise

    def set_setpoint(self, setpoint: Sequence[float]) -> None:
        """The force to exert along the tool's x, y, z (N, each within
        :data:`MAX_FORCE_SETPOINT_N`); the running laws take it at once."""
        value = as_vector(setpoint, 3, "force setpoint")
        if np.max(np.abs(value)) > MAX_FORCE_SETPOINT_N:
            raise ValueError(f"force setpoint components must be within "
                             f"{MAX_FORCE_SETPOINT_N:g} N, "
                             f"got {value.tolist()}")
        with self._lock:
            self.setpoint = value
            self._update_laws()

    def set_axes(self, axes: Sequence[bool]) -> None:
        """Which tool axes are force-controlled (at least one); the running laws take it."""
        chosen = tuple(bool(axis) for axis in axes)
        if len(chosen) != 3 or not all(isinstance(a, (bool, np.bool_)) for a in axes):
            raise ValueError(f"force axes must be 3 booleans, got {axes!r}")
        if not any(chosen):
            raise ValueError("force control needs at least one force axis (x, y or z)")
        with self._lock:
            self.axes = (chosen[0], chosen[1], chosen[2])
            self._update_laws()

    # -- the hooks of the app's loops and tick --------------------------------------------

    def plant(self, dt: float) -> Any:
        """A fresh plant for a loop of period ``dt``: the session's, with the tissue and
        the tool's sensor once one is placed."""
        if self.tissue is None:
            return self._make_plant(dt)
        return MujocoPlant(self._robot, dt, self._plant_choice.settings, tissues=[self.tissue])

    def wrapped(self, controller: Any, dt: float) -> Any:
        """``controller`` through the law when force control is on, else itself."""
        if not self.enabled or self.tissue is None:
            return controller
        wrapper = ForceControlled(controller, self._law(dt))
        self._wrappers.add(wrapper)
        return wrapper

    def motion_distance(self, placement: pin.SE3, target: pin.SE3, ee: int) -> float:
        """How far EE ``ee`` at ``placement`` is from ``target`` along what the operator
        commands (m): with force control on, the law owns the force axes of the first EE's
        tool frame (the tissue, not the target, decides where the tip is along them), so
        the distance counts the other axes only."""
        error = target.translation - placement.translation
        if self.enabled and self.tissue is not None and ee == 0:
            along_tool = placement.rotation.T @ error
            along_tool[list(self.axes)] = 0.0
            return float(np.linalg.norm(along_tool))
        return float(np.linalg.norm(error))

    def feed(self, loops: dict[str, TeleopLoop]) -> None:
        """Each wrapped controller gets its plant's sensor reading of the last period (none
        yet after a reset: it keeps the one it has, zero at first; caller holds the
        lock)."""
        if not self.enabled:
            return
        for loop in loops.values():
            if (loop.controller in self._wrappers and loop.plant is not None
                    and len(loop.plant.measures().tool_wrenches)):
                loop.controller.sense(tool_wrench(loop.plant, 0))

    def measure(self, loop: TeleopLoop) -> None:
        """The main robot's true contact force now, for the plot (caller holds the lock)."""
        if self.tissue is None or loop.plant is None:
            return
        contact = loop.plant.measures().contact_forces
        if len(contact):
            self.history.append((loop.t, *np.asarray(contact[0], dtype=float)))

    def snapshot(self, loops: dict[str, TeleopLoop]) -> dict:
        """What the view draws (caller holds the lock): the settings, the tissue, per robot
        (``contacts``, by loop name) its tool tip and the true contact force on it (world)
        and the sensed one (tool frame), the main robot's also at the top level, and the
        plot's columns (the main robot's)."""
        contacts = {which: self._contact(loop) for which, loop in loops.items()}
        history = np.array(self.history, dtype=float).reshape(-1, 4)
        return {"available": bool(self._plant_choice.physical), "enabled": self.enabled,
                "setpoint": self.setpoint.copy(), "axes": self.axes,
                "tissue": None if self.tissue is None else (self.tissue.point.copy(),
                                                            self.tissue.normal.copy()),
                **contacts["main"], "contacts": contacts, "history": history}

    def _contact(self, loop: TeleopLoop) -> dict:
        """A loop's tool tip, the true contact force on it (world) and the sensed wrench
        (tool frame); zeros without a tissue."""
        contact, sensed = np.zeros(3), np.zeros(6)
        if self.tissue is not None and loop.plant is not None:
            measures = loop.plant.measures()
            if len(measures.contact_forces):
                contact = np.array(measures.contact_forces[0], dtype=float)
                sensed = np.array(measures.tool_wrenches[0], dtype=float)
        tip: pin.SE3 = loop.ee_placements()[0]
        return {"tip": tip.translation.copy(), "contact": contact, "sensed": sensed}

    def _law(self, dt: float) -> HybridForceMotion:
        assert self.tissue is not None
        stiffness = self.tissue.stiffness
        return HybridForceMotion(self.axes, self.setpoint, force_gain_at(stiffness, dt),
                                 stiffness, dt, delay_periods=DELAY_PERIODS,
                                 max_speed=APPROACH_SPEED, filter_cutoff=FILTER_CUTOFF)

    def _update_laws(self) -> None:
        """The running laws take the settings (caller holds the lock)."""
        for wrapper in self._wrappers:
            wrapper.law.set_target(self.axes, self.setpoint)


def force_gain_at(stiffness: float, dt: float) -> float:
    """:data:`FORCE_GAIN`, or :data:`GAIN_SHARE` of the largest gain the law's check
    accepts against ``stiffness`` at period ``dt`` with the force filter's lag when that
    is less (the bound of :func:`teleop.loop.force_stability.force_loop_bound` over
    its margin, divided by ``k_c dt``)."""
    pole = math.exp(-2.0 * math.pi * FILTER_CUTOFF * dt)
    allowed = force_loop_bound(DELAY_PERIODS, pole, 2) / GAIN_MARGIN / (stiffness * dt)
    return min(FORCE_GAIN, GAIN_SHARE * allowed)
