"""The robots of the session: the main one and an optional ghost, each a closed loop with
its controller, and the settings every loop is built with (the constraints' gain, the
CJM's damping, the orientation weight, the task mode, the control rate); switching
controllers, the ghost, and rebuilding the loops (docs/design.md section 5.3).

A new controller, rate or orientation weight needs new loops: they are built outside the
lock (milliseconds of work) and swapped in under it, so the control thread does not wait
for a build. A new task mode (docs/design.md section 20), chosen or resolved by ``auto``
from the constraints placed, changes every loop's in place (:meth:`TeleopLoop.set_task_modes`).
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.collision import CollisionAvoidance
from constraints.validation import as_number, as_vector
from controllers import Controller
from controllers.linalg import DampingPolicy
from teleop.controller_specs import ROBOT, make_controller
from teleop.loop import LoopConfig, StepRecord, TeleopLoop
from teleop.loop.task_modes import AUTO, port_task_modes, task_mode, task_modes, task_weight
from teleop.robots import Robot

from .collisions import CollisionScene
from .force_control import ForceControl
from .homing import WayHome
from .limits import MAX_DAMPING, MAX_GHOST_OFFSET, checked_rate
from .plant import continue_plant
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
    """The robots of :class:`web.app.TeleopApp` (``app.robots``), a component that owns
    them: by robot (``"main"``, ``"ghost"``) their :attr:`specs`, :attr:`loops`,
    :attr:`traces` and :attr:`last_records`; the settings the loops are built with
    (:attr:`config`, :attr:`gain`, :attr:`damping`, :attr:`orientation_weight`,
    :attr:`task_mode`) and where the ghost is drawn (:attr:`ghost_offset`). Its actions take
    the session's lock (a build runs outside it, swapped in under it).

    Parameters
    ----------
    robot : the session's robot.
    lock : the session's lock.
    config : the loops' configuration (rate, gain, speed caps...).
    controller : spec of the main robot's controller.
    q : where the main robot starts (None: ``robot.q_home``).
    constraints : the placed constraints now (every loop holds them).
    collisions : the session's collision avoidance (every controller holds it while on).
    force : the force control (it wraps the controllers and makes the loops' plants).
    homing : the way home (followed in full pose).
    recorder : the session's recording (it gets the task modes).
    ros2 : the robot over ROS 2 (no ghost then), or None.
    acceleration_limits : whether the controllers keep the joint acceleration limits.
    jerk_limit : a jerk limit (rad/s^3) every controller keeps, or None.
    """

    def __init__(self, robot: Robot, lock: threading.RLock, config: LoopConfig,
                 controller: str, q: np.ndarray | None,
                 constraints: Callable[[], list[Constraint]], collisions: CollisionScene,
                 force: ForceControl, homing: WayHome, recorder: SessionRecording,
                 ros2: Ros2Robot | None, acceleration_limits: bool,
                 jerk_limit: float | None) -> None:
        self.robot = robot
        self._lock = lock
        self._build_lock = threading.Lock()  # one loop build at a time (outside _lock)
        self._constraints = constraints
        self._collisions = collisions
        self._force = force
        self._homing = homing
        self._recorder = recorder
        self._ros2 = ros2
        self.acceleration_limits = acceleration_limits
        self.jerk_limit = jerk_limit
        self.config = config
        self.gain = 100.0
        self.damping = 0.0
        #: weight of the EE twists' angular entries (1: full poses; lower lets each
        #: instrument's orientation give way to its tip position, docs/design.md 11.2)
        self.orientation_weight = 1.0
        #: what the operator commands of each EE (docs/design.md section 20): a mode of
        #: ``teleop.loop.task_modes.TASK_MODES`` or ``auto``, what the ports allow
        self.task_mode = AUTO
        self.specs = {"main": controller}
        self.loops: dict[str, TeleopLoop] = {"main": self.make_loop(controller, q=q)}
        self.traces: dict[str, Trace] = {"main": Trace()}
        self.last_records: dict[str, StepRecord | None] = {"main": None}
        self.ghost_offset = default_ghost_offset(robot)

    @property
    def now(self) -> float:
        """The session's time (s): the main robot's loop time."""
        return self.loops["main"].t

    def make_loop(self, spec: str, q: np.ndarray | None = None,
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
            constraints = self._constraints()
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
        controller.set_collisions(self._collisions.attached(avoidance, collisions_on))
        return TeleopLoop(self.robot, self._force.wrapped(controller, config.dt), q0=q,
                          config=config, plant=self._force.plant(config.dt), task_modes=modes)

    @staticmethod
    def _twist_weight(modes: tuple[str, ...], orientation_weight: float) -> np.ndarray:
        """The controllers' task weight: the modes' rows, the angular ones times the
        orientation weight."""
        angular = orientation_weight
        return task_weight(modes) * np.tile([1.0, 1.0, 1.0, angular, angular, angular],
                                            len(modes))

    def apply_task_modes(self) -> None:
        """Every loop on the task modes the session resolves to now, when they changed
        (caller holds the lock); a recording gets them."""
        modes = self.resolved_task_modes()
        if modes == self.loops["main"].task_modes:
            return
        for loop in self.loops.values():
            loop.set_task_modes(modes, self._twist_weight(modes, self.orientation_weight))
        self._recorder.task_modes(modes)

    def resolved_task_modes(self, constraints: list[Constraint] | None = None,
                            task_mode: str | None = None) -> tuple[str, ...]:
        """The task mode of each EE (docs/design.md section 20): ``task_mode`` (default:
        the session's) for every EE, ``auto`` resolved to what the chain's constraints
        (default: the placed ones) allow; the full pose while "Home" runs (:mod:`.homing`)."""
        mode = self.task_mode if task_mode is None else task_mode
        if self._homing.active:  # the way home is followed in full pose (section 20.3)
            mode = "pose"
        if constraints is None:
            constraints = self._constraints()
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

    def sync_constraints(self) -> None:
        """Every loop on the placed constraints and the task modes they resolve to
        (``auto``; caller holds the lock)."""
        constraints = self._constraints()
        for loop in self.loops.values():
            loop.set_constraints(constraints)
        self.apply_task_modes()

    def _build_inputs(self) -> tuple:
        """What a loop build reads besides its own arguments: if any of it changed while
        a build ran outside the lock, the build is redone under the lock."""
        return (tuple(id(constraint) for constraint in self._constraints()), self.gain,
                self.damping, self.config, self.orientation_weight, self.task_mode,
                id(self._homing.run), tuple(self.specs.items()),
                id(self._collisions.attached()))

    def rebuild(self, specs: dict[str, str], config: LoopConfig | None = None,
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
                constraints = self._constraints()
                starts = {which: self.loops.get(which, self.loops["main"]).q.copy()
                          for which in specs}
            loops = {which: self.make_loop(spec, q=starts[which], constraints=constraints,
                                           config=config, orientation_weight=weight)
                     for which, spec in specs.items()}  # raises ValueError: nothing changed
            with self._lock:
                if self._build_inputs() != inputs:  # changed meanwhile: build it again here
                    constraints = self._constraints()
                    loops = {which: self.make_loop(spec, constraints=constraints,
                                                   config=config, orientation_weight=weight)
                             for which, spec in specs.items()}
                for which, loop in loops.items():  # the state they replace, as of now
                    old = self.loops.get(which, self.loops["main"])
                    loop.q = old.q.copy()
                    loop.t = old.t
                    continue_plant(self.loops.get(which), loop)
                if config is not self.config:  # every other loop follows the new period
                    others = {which: self.make_loop(self.specs[which], q=loop.q.copy(),
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

    def restore(self, loops: dict[str, TeleopLoop], specs: dict[str, str],
                config: LoopConfig, gain: float, damping: float, orientation_weight: float,
                task_mode: str) -> None:
        """A scene's robots: its ``loops`` of controllers ``specs`` (built with
        :meth:`make_loop` from its settings) and those settings, the traces started
        afresh (caller holds the lock)."""
        self.config, self.gain, self.damping = config, gain, damping
        self.orientation_weight, self.task_mode = orientation_weight, task_mode
        self.specs, self.loops = specs, loops
        self.traces = {which: Trace() for which in loops}
        self.last_records = {which: None for which in loops}

    def set_controller(self, spec: str) -> None:
        """Switch the main robot's controller, keeping its state."""
        self.rebuild({"main": spec})

    def set_ghost(self, spec: str | None) -> None:
        """Show a second robot driven by ``spec`` from the same target (None removes it).

        It starts where the main robot is, at the same time, so the two histories line up.
        """
        if self._ros2 is not None:
            self._ros2.refuse_ghost(spec)
        if not spec:
            with self._lock:
                for store in (self.loops, self.specs, self.traces, self.last_records,
                              self._collisions.rows):
                    store.pop("ghost", None)
            return
        self.rebuild({"ghost": spec})

    def set_ghost_offset(self, offset) -> None:
        """Where the ghost is drawn, from the main robot (world, m); zero overlays them."""
        offset = as_vector(offset, 3, "ghost offset")
        if np.linalg.norm(offset) > MAX_GHOST_OFFSET:
            raise ValueError(f"the ghost offset must be at most {MAX_GHOST_OFFSET:g} m long, "
                             f"got {np.linalg.norm(offset):.3g} m")
        with self._lock:
            self.ghost_offset = offset

    def set_gain(self, gain: float) -> None:
        """Gain K (1/s) of every constraint: the drift feedback of the equalities, the
        approach rate of the one-sided constraints, stable at this rate by
        :attr:`constraints.Constraint.gain_rule`. A gain some placed constraint
        cannot take at this rate raises ``ValueError`` naming the gain and changes
        nothing."""
        gain = as_number(gain, "gain")
        with self._lock:
            dt = self.config.dt
            if not Constraint.gain_rule.is_stable(gain, dt):
                raise ValueError(f"gain must be in [0, {Constraint.gain_rule.bound(dt):g}) "
                                 f"1/s at this rate, got {gain:g}")
            previous = self.gain
            constraints = self._constraints()
            try:  # each constraint checks the gain at its controllers' period
                for constraint in constraints:
                    constraint.gain = gain
                self.gain = gain
                self.sync_constraints()
            except ValueError:
                self.gain = previous
                for constraint in constraints:
                    constraint.gain = previous
                self.sync_constraints()
                raise

    def set_damping(self, damping: float) -> None:
        """Constant DLS damping lambda of the CJM (paper eq 35), in [0, MAX_DAMPING]."""
        damping = as_number(damping, "damping", 0.0, maximum=MAX_DAMPING)
        with self._lock:
            self.damping = damping
            for loop in self.loops.values():
                self._apply_damping(loop.controller)

    def set_orientation_weight(self, weight: float) -> None:
        """Weight in [0, 1] of every EE twist's angular entries against the linear ones
        (every controller's ``twist_weight``): 1 asks for full poses; with two trocars on
        one torso, which leave 11 joint directions for 12 entries, a lower weight lets the
        orientations give way so the tips go where they are dragged. Rebuilds the loops,
        keeps the state."""
        weight = as_number(weight, "orientation weight", 0.0, maximum=1.0)
        self.rebuild(dict(self.specs), orientation_weight=weight)

    def set_task_mode(self, mode: str) -> None:
        """What the operator commands of every EE (docs/design.md section 20): ``pose``,
        ``position_roll`` (position and roll about the tool axis), ``position``, or
        ``auto`` (position and roll on a chain with a port, else the full pose); the
        rows left out go to the controllers' null space. Every loop changes in place; an
        unknown mode raises ``ValueError`` and changes nothing."""
        if mode != AUTO:
            task_mode(mode)  # ValueError naming the modes
        with self._lock:
            self.task_mode = mode
            self.apply_task_modes()

    def set_rate(self, rate: float) -> None:
        """Control rate (Hz), in [MIN_RATE, MAX_RATE]; rebuilds the loops (QP limits depend
        on dt), keeps the state."""
        rate = checked_rate(rate)
        self.rebuild(dict(self.specs), config=dataclasses.replace(self.config, rate=rate))
