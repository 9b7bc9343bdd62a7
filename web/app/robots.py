"""The robots of the session: the main one and an optional ghost, each a closed loop with
its controller; switching controllers, the ghost, and rebuilding the loops (docs/design.md
section 5.3).

A new controller, rate or orientation weight needs new loops: they are built outside the
lock (milliseconds of work) and swapped in under it, so the control thread does not wait
for a build. A new task mode (docs/design.md section 20), chosen or resolved by ``auto``
from the constraints placed, changes every loop's in place (:meth:`TeleopLoop.set_task_modes`).
"""

from __future__ import annotations

import threading

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.collision import CollisionAvoidance
from constraints.validation import as_vector
from controllers import Controller
from controllers.linalg import DampingPolicy
from teleop.controller_specs import ROBOT, make_controller
from teleop.loop import LoopConfig, StepRecord, TeleopLoop
from teleop.loop.task_modes import AUTO, port_task_modes, task_modes, task_weight
from teleop.robots import Robot

from .collisions import CollisionScene
from .force_control import ForceControl
from .homing import WayHome
from .limits import MAX_GHOST_OFFSET
from .plant import PlantChoice, continue_plant
from .ros2_robot import Ros2Robot
from .recording import SessionRecording
from .trace import Trace


def default_ghost_offset(robot: Robot) -> np.ndarray:
    """Where the ghost goes beside the main robot: sideways from the direction the arms
    reach at home (their EEs' mean), to the left as seen from the front (where the page's
    first view looks from: the control panel covers the right of the view), by the
    robot's width in that direction plus a margin."""
    model = robot.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, robot.q_home)
    points = np.array([frame.translation for frame in data.oMf])
    reach = (np.mean([data.oMf[frame].translation for frame in robot.ee_frame_ids], axis=0)
             - data.oMf[0].translation)
    reach[2] = 0.0
    if np.linalg.norm(reach) < 1e-6:
        reach = np.array([1.0, 0.0, 0.0])
    side = np.cross(reach / np.linalg.norm(reach), [0.0, 0.0, 1.0])
    width = float(np.ptp(points @ side))
    return (width + 0.4) * side


class Robots:
    """The loops of :class:`web.app.TeleopApp` by robot (``"main"``, ``"ghost"``): their
    specs, loops, traces and last measured records."""

    robot: Robot
    config: LoopConfig
    damping: float
    gain: float
    orientation_weight: float
    task_mode: str
    homing: WayHome
    entries: dict
    specs: dict[str, str]
    loops: dict[str, TeleopLoop]
    traces: dict[str, Trace]
    last_records: dict[str, StepRecord | None]
    collisions: CollisionScene
    recorder: SessionRecording
    ghost_offset: np.ndarray
    plant: PlantChoice
    force: ForceControl
    acceleration_limits: bool
    jerk_limit: float | None
    ros2: Ros2Robot | None
    _lock: threading.RLock
    _build_lock: threading.Lock

    def _make_loop(self, spec: str, q: np.ndarray | None = None,
                   constraints: list[Constraint] | None = None,
                   config: LoopConfig | None = None,
                   orientation_weight: float | None = None,
                   damping: float | None = None, avoidance: CollisionAvoidance | None = None,
                   collisions_on: bool | None = None, task_mode: str | None = None) -> TeleopLoop:
        """A loop of controller ``spec``: the session's constraints, period, weight,
        damping, collision avoidance, whether the controller holds it and task mode, unless
        given. The controller's task weight is the task modes' rows (docs/design.md section
        20) times the orientation weight on the angular entries."""
        if constraints is None:
            constraints = [e.constraint for e in self.entries.values()]
        config = config or self.config
        weight = self.orientation_weight if orientation_weight is None else orientation_weight
        modes = self.resolved_task_modes(constraints, task_mode)
        twist_weight = self._twist_weight(modes, weight)
        controller = make_controller(spec, self.robot, constraints, dt=config.dt,
                                     twist_weight=None if np.all(twist_weight == 1.0)
                                     else twist_weight,
                                     acceleration_limit=ROBOT if self.acceleration_limits
                                     else None, jerk_limit=self.jerk_limit)
        self._apply_damping(controller, damping)
        controller.set_collisions(self.collisions.attached(avoidance, collisions_on))
        return TeleopLoop(self.robot, self.force.wrapped(controller, config.dt), q0=q,
                          config=config, plant=self.force.plant(config.dt), task_modes=modes)

    @staticmethod
    def _twist_weight(modes: tuple[str, ...], orientation_weight: float) -> np.ndarray:
        """The controllers' task weight: the modes' rows, the angular ones times the
        orientation weight."""
        angular = orientation_weight
        return task_weight(modes) * np.tile([1.0, 1.0, 1.0, angular, angular, angular],
                                            len(modes))

    def _apply_task_modes(self) -> None:
        """Every loop on the task modes the session resolves to now, when they changed
        (caller holds the lock); a recording gets them."""
        modes = self.resolved_task_modes()
        if modes == self.loops["main"].task_modes:
            return
        for loop in self.loops.values():
            loop.set_task_modes(modes, self._twist_weight(modes, self.orientation_weight))
        self.recorder.task_modes(modes)

    def resolved_task_modes(self, constraints: list[Constraint] | None = None,
                            task_mode: str | None = None) -> tuple[str, ...]:
        """The task mode of each EE (docs/design.md section 20): ``task_mode`` (default:
        the session's) for every EE, ``auto`` resolved to what the chain's constraints
        (default: the placed ones) allow; the full pose while "Home" runs (:mod:`.homing`)."""
        mode = self.task_mode if task_mode is None else task_mode
        if self.homing.active:  # the way home is followed in full pose (section 20.3)
            mode = "pose"
        if constraints is None:
            constraints = [e.constraint for e in self.entries.values()]
        if mode == AUTO:
            return port_task_modes(self.robot, constraints)
        return task_modes(mode, len(self.robot.ee_frames))

    def _apply_damping(self, controller: Controller, damping: float | None = None) -> None:
        """The operator's constant damping on a controller that damps its task
        (:attr:`controllers.Controller.policy`), its rising damping near singularity kept."""
        if controller.policy is not None:
            old = controller.policy
            controller.policy = DampingPolicy(self.damping if damping is None else damping,
                                              old.threshold, old.max_damping)

    def _sync_constraints(self) -> None:
        """Every loop on the placed constraints and the task modes they resolve to
        (``auto``; caller holds the lock)."""
        constraints = [e.constraint for e in self.entries.values()]
        for loop in self.loops.values():
            loop.set_constraints(constraints)
        self._apply_task_modes()

    def _build_inputs(self) -> tuple:
        """What a loop build reads besides its own arguments: if any of it changed while
        a build ran outside the lock, the build is redone under the lock."""
        return (tuple(id(e.constraint) for e in self.entries.values()), self.gain,
                self.damping, self.config, self.orientation_weight, self.task_mode,
                id(self.homing.run), tuple(self.specs.items()), id(self.collisions.attached()))

    def _rebuild(self, specs: dict[str, str], config: LoopConfig | None = None,
                 orientation_weight: float | None = None) -> None:
        """Robots ``specs`` (``{"main": spec, "ghost": spec}``) with new loops at ``config``
        and ``orientation_weight`` (default: the current ones), each starting from the
        state of the loop it replaces (a new ghost from the main robot's); the others keep
        theirs. All or nothing: a spec or gain that cannot be built raises ``ValueError``
        and changes nothing."""
        with self._build_lock:
            with self._lock:
                inputs = self._build_inputs()
                config = config or self.config
                weight = self.orientation_weight if orientation_weight is None \
                    else orientation_weight
                constraints = [e.constraint for e in self.entries.values()]
                starts = {which: self.loops.get(which, self.loops["main"]).q.copy()
                          for which in specs}
            loops = {which: self._make_loop(spec, q=starts[which], constraints=constraints,
                                            config=config, orientation_weight=weight)
                     for which, spec in specs.items()}  # raises ValueError: nothing changed
            with self._lock:
                if self._build_inputs() != inputs:  # changed meanwhile: build it again here
                    constraints = [e.constraint for e in self.entries.values()]
                    loops = {which: self._make_loop(spec, constraints=constraints,
                                                    config=config, orientation_weight=weight)
                             for which, spec in specs.items()}
                for which, loop in loops.items():  # the state they replace, as of now
                    old = self.loops.get(which, self.loops["main"])
                    loop.q = old.q.copy()
                    loop.t = old.t
                    continue_plant(self.loops.get(which), loop)
                if config is not self.config:  # every other loop follows the new period
                    others = {which: self._make_loop(self.specs[which], q=loop.q.copy(),
                                                     constraints=constraints, config=config,
                                                     orientation_weight=weight)
                              for which, loop in self.loops.items() if which not in loops}
                    for which, loop in others.items():
                        loop.t = self.loops[which].t
                        continue_plant(self.loops[which], loop)
                    loops.update(others)
                for which in loops:
                    if which not in self.traces:
                        self.traces[which] = Trace()
                        self.last_records[which] = None
                self.config, self.orientation_weight = config, weight
                self.specs.update(specs)
                self.loops.update(loops)

    def set_controller(self, spec: str) -> None:
        """Switch the main robot's controller, keeping its state."""
        self._rebuild({"main": spec})

    def set_ghost(self, spec: str | None) -> None:
        """Show a second robot driven by ``spec`` from the same target (None removes it).

        It starts where the main robot is, at the same time, so the two histories line up.
        """
        if self.ros2 is not None:
            self.ros2.refuse_ghost(spec)
        if not spec:
            with self._lock:
                for store in (self.loops, self.specs, self.traces, self.last_records,
                              self.collisions.rows):
                    store.pop("ghost", None)
            return
        self._rebuild({"ghost": spec})

    def set_ghost_offset(self, offset) -> None:
        """Where the ghost is drawn, from the main robot (world, m); zero overlays them."""
        offset = as_vector(offset, 3, "ghost offset")
        if np.linalg.norm(offset) > MAX_GHOST_OFFSET:
            raise ValueError(f"the ghost offset must be at most {MAX_GHOST_OFFSET:g} m long, "
                             f"got {np.linalg.norm(offset):.3g} m")
        with self._lock:
            self.ghost_offset = offset
