"""One controller's run as columns, and its summary metrics (the keys of metrics.json)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from teleop.loop import SAFETY_TOLERANCE
from teleop.plants.interface import InterfaceFault

from .smoothness import HIGH_FREQUENCY_HZ, joint_jerk_rms, power_fraction_above

#: per-controller numeric keys of metrics.json, in order (the CSV's columns; documented in
#: metrics.schema.json and docs/design.md sections 7 and 15)
METRIC_KEYS = (
    "constraint_error_max_m", "constraint_error_rms_m",
    "constraint_velocity_residual_max_mps", "constraint_velocity_max_mps",
    "constraint_velocity_rms_mps", "barrier_penetration_max_m",
    "ee_position_error_max_m", "ee_position_error_rms_m",
    "ee_orientation_error_max_rad", "ee_orientation_error_rms_rad",
    "joint_limit_violation_max_rad", "failed_steps",
    "step_time_median_us", "step_time_p99_us", "step_time_max_us", "tick_time_median_us",
    "joint_velocity_deviation_max_radps",
)

#: per-controller keys of the robot's body and the run's smoothness (docs/design.md section
#: 17.3), after :data:`METRIC_KEYS` in the CSV: null where they do not apply (no hole; the
#: port, torque and saturation keys on a plant without a body; the interface's with its
#: check off)
BODY_METRIC_KEYS = (
    "hole_error_max_m", "port_force_max_n", "port_force_rms_n", "port_displacement_max_m",
    "torque_ratio_max", "actuator_saturated_steps", "joint_jerk_rms_radps3",
    "ee_velocity_power_above_3hz", "port_force_spring_max_n", "port_force_damper_max_n",
    "port_force_peak_spring_n", "port_force_peak_damper_n", "interface_faults",
    "interface_first_fault_t_s",
)

#: per-controller keys of collision avoidance (docs/design.md section 18.6), between
#: :data:`METRIC_KEYS` and :data:`BODY_METRIC_KEYS` in the CSV: null without collision
#: avoidance (the contact keys: also on a plant without a body)
COLLISION_METRIC_KEYS = (
    "minimum_distance_m", "penetration_steps", "safety_violation_steps", "contact_steps",
    "contact_depth_max_m",
)


@dataclass
class RunResult:
    """One controller's run: per-step columns and what went wrong.

    Attributes
    ----------
    controller : the controller spec.
    columns : per-step scalars, one array per ``teleop.loop.RECORD_FIELDS`` name.
    constraint_velocity : (steps, rows) every equality row's ``C v_c`` relative to its
        geometry (m/s, docs/design.md section 15.2), NaN where the row does not exist.
    constraint_velocity_labels : the rows' names in words, one per column.
    drift_velocity : (steps, rows) the drift correction ``-K e`` of each row (m/s).
    operator_linear_velocity, commanded_linear_velocity, actual_linear_velocity :
        (steps, 3) world-frame EE linear velocities: the filtered target's, the commanded
        twist's, the one achieved.
    statuses : (steps,) the loop's status each step: the controller's, or
        ``constraint_degraded`` when the supervisor measured beyond tolerance
        (docs/design.md 5.2).
    ee_frames : the robot's EE frames, in order.
    ee_position_errors, ee_orientation_errors : (steps, EEs) each EE's error against its
        target (m, rad); the ``ee_*`` columns are the worst EE's.
    constraint_errors : per constraint name (``teleop.loop.constraint_names``), its
        violation each step (m: a hole's axis offset, a barrier's penetration), NaN while
        it does not exist.
    joint_velocity_deviation : (steps,) ``max_j |qd_j - qd_ref,j|`` of this controller's
        solve at the reference run's ``q`` and twist (rad/s, docs/design.md section 15.3),
        zeros for the reference itself; None when not computed.
    failure_messages : the first failures, with their time.
    failure_summary : every failed step counted by its message (``message``, ``count``,
        ``first_step``, ``first_t_s``), the most frequent first.
    status_counts : steps per status (the loop's, :attr:`statuses`).
    controller_status_counts : steps per the controller's own step status.
    supervisor_first_action : the first period the supervisor scaled or held the twist, in
        words with its time (None: it never acted).
    solver_messages : what the solvers wrote or warned during the run, each distinct line
        with its count (docs/design.md section 15.5).
    commanded_joint_velocity : (steps, nv) the command of each step (rad/s).
    actual_linear_velocities : (steps, EEs, 3) each EE's achieved linear velocity (world).
    port_names : the constraints with a wall (the holes), by name, in order of appearance.
    port_forces : per port name, (steps, 3) the wall's force on the instrument (N, world),
        NaN while the port does not exist; None on a plant without a body.
    port_displacements : per port name, (steps,) the tissue's lateral displacement (m).
    port_spring_forces : per port name, (steps, 3) the spring part ``-k (P - c)`` of the
        wall's force (N; the rest is the damper's, docs/design.md 17.2); None likewise.
    torque_ratio : (steps,) max over joints of |drive torque| / effort limit; None likewise.
    actuator_saturated : (steps,) some drive held at its effort limit; None likewise.
    closest_pairs : (steps,) the pair of the ``minimum_distance`` column each step ("" when
        none was measured).
    safety_distance : the collision avoidance's ``d_s`` (m); None: the run had none.
    contacts : (steps,) the simulated robot's contacts at each period's end (robot-robot
        and robot-obstacle pairs of the collision avoidance); None on a plant without a body.
    contact_depths : (steps,) the deepest of them (m, 0 without contact); None likewise.
    interface_limits : the plant's interface mode (``off``, ``count``, ``strict``,
        docs/design.md 17.1); None on a plant without a body.
    interface_faults : (steps,) the interface refused (``strict``) or counted the step's
        command; None on a plant without a body.
    interface_first_fault : the time (s) and the fault of the first, None: none.
    """

    controller: str
    columns: dict[str, np.ndarray]
    constraint_velocity: np.ndarray
    constraint_velocity_labels: list[str]
    drift_velocity: np.ndarray
    operator_linear_velocity: np.ndarray
    commanded_linear_velocity: np.ndarray
    actual_linear_velocity: np.ndarray
    statuses: np.ndarray
    ee_frames: tuple[str, ...] = ()
    ee_position_errors: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    ee_orientation_errors: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    constraint_errors: dict[str, np.ndarray] = field(default_factory=dict)
    joint_velocity_deviation: np.ndarray | None = None
    failure_messages: list[str] = field(default_factory=list)
    failure_summary: list[dict] = field(default_factory=list)
    status_counts: dict[str, int] = field(default_factory=dict)
    controller_status_counts: dict[str, int] = field(default_factory=dict)
    supervisor_first_action: str | None = None
    solver_messages: dict[str, int] = field(default_factory=dict)
    commanded_joint_velocity: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    actual_linear_velocities: np.ndarray = field(default_factory=lambda: np.zeros((0, 0, 3)))
    port_names: list[str] = field(default_factory=list)
    port_forces: dict[str, np.ndarray] | None = None
    port_displacements: dict[str, np.ndarray] | None = None
    torque_ratio: np.ndarray | None = None
    actuator_saturated: np.ndarray | None = None
    closest_pairs: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=object))
    safety_distance: float | None = None
    contacts: np.ndarray | None = None
    contact_depths: np.ndarray | None = None
    port_spring_forces: dict[str, np.ndarray] | None = None
    interface_limits: str | None = None
    interface_faults: np.ndarray | None = None
    interface_first_fault: tuple[float, InterfaceFault] | None = None

    def collision_metrics(self) -> dict[str, float | int | str | None]:
        """The minimum distance over the run (m; null without collision avoidance or when
        no pair came within the broadphase's reach), its pair, the steps with a
        penetration (``d < 0``) and with a safety violation (``d < d_s - 0.5 mm``,
        ``teleop.loop.SAFETY_TOLERANCE``); the plant's contact steps and deepest contact."""
        measured = self.safety_distance is not None
        distance = self.columns.get("minimum_distance", np.zeros(0))
        finite = np.isfinite(distance)
        lowest = int(np.argmin(np.where(finite, distance, np.inf))) if finite.any() else None
        bodily = measured and self.contacts is not None
        return {
            "minimum_distance_m": (float(distance[lowest]) if measured and lowest is not None
                                   else None),
            "closest_pair": (str(self.closest_pairs[lowest]) if measured and lowest is not None
                             else None),
            "penetration_steps": int(np.sum(distance < 0.0)) if measured else None,
            "safety_violation_steps": (int(np.sum(distance < self.safety_distance
                                                  - SAFETY_TOLERANCE)) if measured else None),
            "contact_steps": int(np.sum(self.contacts > 0)) if bodily else None,
            "contact_depth_max_m": (float(np.max(self.contact_depths, initial=0.0)) if bodily
                                    else None),
        }

    def supervisor_metrics(self) -> dict[str, float | int | str | None]:
        """What the supervisor measured at the sensed configuration and did
        (docs/design.md 5.2): the largest measured constraint error and port force (null
        when the plant measured none), the steps it scaled and held the operator's motion,
        the smallest scale, the largest offset of the supervised target from the
        operator's (distance and angle), its first action in words."""
        c = self.columns
        scale = c.get("supervisor_scale", np.ones(0))
        offset = c.get("supervisor_target_offset", np.zeros(0))
        angle = c.get("supervisor_target_offset_angle", np.zeros(0))
        measured = c.get("measured_constraint_error", np.zeros(0))
        force = c.get("measured_port_force", np.zeros(0))
        force = force[np.isfinite(force)]
        return {
            "measured_error_max_m": float(np.max(measured, initial=0.0)),
            "measured_port_force_max_n": float(np.max(force)) if force.size else None,
            "scaled_steps": int(np.sum((scale > 0.0) & (scale < 1.0))),
            "held_steps": int(np.sum(scale == 0.0)),
            "scale_min": float(np.min(scale, initial=1.0)),
            "target_offset_max_m": float(np.max(offset, initial=0.0)),
            "target_offset_angle_max_rad": float(np.max(angle, initial=0.0)),
            "first_action": self.supervisor_first_action,
        }

    def wall_metrics(self) -> dict[str, float | None]:
        """The largest spring and damper parts of the wall's force over steps and ports,
        and the two parts where ``|F|`` peaks (N; docs/design.md 17.2; the parts peak at
        different times, the damper's with the velocity); null on a plant without a body
        (the peak's also without a port)."""
        if self.port_spring_forces is None:
            return dict.fromkeys(("port_force_spring_max_n", "port_force_damper_max_n",
                                  "port_force_peak_spring_n", "port_force_peak_damper_n"))
        springs, dampers = self._wall_parts()
        names = list(springs)
        spring, damper = (np.column_stack([parts[name] for name in names]) if names
                          else np.zeros((self.steps, 0)) for parts in (springs, dampers))
        total = np.column_stack([self.port_force_magnitudes()[name] for name in names]) \
            if names else np.zeros((self.steps, 0))
        finite = np.isfinite(total)
        peak = (np.unravel_index(np.argmax(np.where(finite, total, -np.inf)), total.shape)
                if finite.any() else None)
        return {"port_force_spring_max_n": float(np.max(spring[finite], initial=0.0)),
                "port_force_damper_max_n": float(np.max(damper[finite], initial=0.0)),
                "port_force_peak_spring_n": None if peak is None else float(spring[peak]),
                "port_force_peak_damper_n": None if peak is None else float(damper[peak])}

    def _wall_parts(self) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        """Per port, ``|F_spring|`` and ``|F - F_spring|`` each step (N, NaN while the port
        does not exist)."""
        springs = self.port_spring_forces or {}
        forces = self.port_forces or {}
        return ({name: np.linalg.norm(springs[name], axis=1) for name in springs},
                {name: np.linalg.norm(forces[name] - springs[name], axis=1)
                 for name in springs})

    def interface_metrics(self) -> dict[str, float | int | str | None]:
        """The interface's faults (docs/design.md 17.1): their number, the first's time,
        joint and words; the count null where nothing was checked (no body, or the check
        off), the first's keys null without a fault."""
        checked = self.interface_limits not in (None, "off") and self.interface_faults is not None
        first = self.interface_first_fault
        return {
            "interface_faults": int(np.sum(self.interface_faults)) if checked else None,
            "interface_first_fault_t_s": None if first is None else first[0],
            "interface_first_fault_joint": None if first is None else first[1].joint,
            "interface_first_fault": (None if first is None
                                      else f"t={first[0]:.3f}s: {first[1].describe()}"),
        }

    @property
    def dt(self) -> float:
        """The control period (s), from the step times (0 with fewer than two steps)."""
        t = self.columns["t"]
        return float(t[1] - t[0]) if len(t) > 1 else 0.0

    def port_force_magnitudes(self) -> dict[str, np.ndarray]:
        """Per port, ``|F|`` each step (N; NaN while the port does not exist); empty on a
        plant without a body."""
        return {name: np.linalg.norm(forces, axis=1)
                for name, forces in (self.port_forces or {}).items()}

    @property
    def steps(self) -> int:
        return len(self.columns["t"])

    def metrics(self) -> dict[str, float | int | str | dict | list | None]:
        """The summary of docs/design.md sections 7 and 15 (units in the key names): the
        ``ee_*`` keys are over the per-step worst EE; ``end_effectors`` has each EE's,
        ``constraints`` each constraint's error."""
        c = self.columns

        def rms(x: np.ndarray) -> float:
            x = x[np.isfinite(x)]
            return float(np.sqrt(np.mean(np.square(x)))) if x.size else 0.0

        def top(x: np.ndarray) -> float:
            x = x[np.isfinite(x)]
            return float(np.max(np.abs(x))) if x.size else 0.0

        step = c["step_time_us"]
        deviation = self.joint_velocity_deviation
        forces = self.port_force_magnitudes()
        all_forces = np.concatenate([f for f in forces.values()]) if forces else np.zeros(0)
        displacements = (np.concatenate(list(self.port_displacements.values()))
                         if self.port_displacements else np.zeros(0))
        physical = self.port_forces is not None
        springs, dampers = self._wall_parts()
        holes = [self.constraint_errors[name] for name in self.port_names
                 if name in self.constraint_errors]
        return {
            "constraint_error_max_m": top(c["constraint_error"]),
            "constraint_error_rms_m": rms(c["constraint_error"]),
            "constraint_velocity_residual_max_mps": top(c["constraint_velocity_residual"]),
            "constraint_velocity_max_mps": top(self.constraint_velocity.ravel()),
            "constraint_velocity_rms_mps": rms(self.constraint_velocity.ravel()),
            "barrier_penetration_max_m": top(c["barrier_penetration"]),
            "ee_position_error_max_m": top(c["ee_position_error"]),
            "ee_position_error_rms_m": rms(c["ee_position_error"]),
            "ee_orientation_error_max_rad": top(c["ee_orientation_error"]),
            "ee_orientation_error_rms_rad": rms(c["ee_orientation_error"]),
            "joint_limit_violation_max_rad": top(c["joint_limit_violation"]),
            "failed_steps": int(np.sum(c["failed"])),
            "step_time_median_us": float(np.median(step)) if step.size else 0.0,
            "step_time_p99_us": float(np.percentile(step, 99)) if step.size else 0.0,
            "step_time_max_us": top(step),
            "tick_time_median_us": float(np.median(c["tick_time_us"])) if step.size else 0.0,
            "joint_velocity_deviation_max_radps": None if deviation is None else top(deviation),
            "hole_error_max_m": top(np.concatenate(holes)) if holes else None,
            "port_force_max_n": top(all_forces) if physical else None,
            "port_force_rms_n": rms(all_forces) if physical else None,
            "port_displacement_max_m": top(displacements) if physical else None,
            "torque_ratio_max": top(self.torque_ratio) if physical else None,
            "actuator_saturated_steps": (int(np.sum(self.actuator_saturated)) if physical
                                         else None),
            "joint_jerk_rms_radps3": joint_jerk_rms(self.commanded_joint_velocity, self.dt),
            "ee_velocity_power_above_3hz": max(
                (power_fraction_above(self.actual_linear_velocities[:, i], self.dt,
                                      HIGH_FREQUENCY_HZ)
                 for i in range(self.actual_linear_velocities.shape[1])), default=0.0),
            **self.wall_metrics(),
            **self.interface_metrics(),
            **self.collision_metrics(),
            "first_failure": self.failure_messages[0] if self.failure_messages else None,
            "failures": [dict(entry) for entry in self.failure_summary],
            "status_counts": dict(self.status_counts),
            "controller_status_counts": dict(self.controller_status_counts),
            "supervisor": self.supervisor_metrics(),
            "solver_messages": dict(self.solver_messages),
            "end_effectors": {frame: {
                "position_error_max_m": top(self.ee_position_errors[:, i]),
                "position_error_rms_m": rms(self.ee_position_errors[:, i]),
                "orientation_error_max_rad": top(self.ee_orientation_errors[:, i]),
                "orientation_error_rms_rad": rms(self.ee_orientation_errors[:, i]),
            } for i, frame in enumerate(self.ee_frames)},
            "constraints": {name: {"error_max_m": top(errors), "error_rms_m": rms(errors)}
                            for name, errors in self.constraint_errors.items()},
            "ports": {name: {
                "force_max_n": top(forces[name]), "force_rms_n": rms(forces[name]),
                "displacement_max_m": top(self.port_displacements[name]),
                "spring_force_max_n": top(springs[name]),
                "damper_force_max_n": top(dampers[name]),
            } for name in self.port_names} if physical else {},
        }
