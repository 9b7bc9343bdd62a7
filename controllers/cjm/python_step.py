"""The CJM step in Python: the readable reference of docs/design.md sections 4-9.

:class:`PythonStep` runs one step of :class:`controllers.cjm.controller.CJMController`
from its :class:`~controllers.cjm.step_setup.StepSetup`: the kinematics, the equality
rows, the barriers' and the collision rows' active set, the analytical or general form,
saturation in the null space when the command leaves the joint box, the clip guard, and a
:class:`~controllers.cjm.report.StepReport` of what happened. The compiled step
(:mod:`controllers.cjm.compiled`) does the same in C++.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from constraints.collision import CollisionRows

from ..base import StepStatus, checked_inputs
from ..joint_acceleration import braked_lower, braked_pairs
from .analytical import SquarePreChain, solve_redundant_pre_chain
from .general import solve_general
from .report import Event, StepReport
from .saturation import Saturation, saturate_in_null_space
from .saturation_walk import held_sides, saturate_around_previous, saturate_from_held
from .step_setup import StepSetup
from .tolerances import BARRIER_TOLERANCE, EQUALITY_TOLERANCE, PAPER_FORM_MIN_A, StepTolerances


class PythonStep:
    """One controller's Python step: ``solve(q, twist) -> (qd, report)``.

    ``data`` is the controller's ``pin.Data``: after a step it holds the kinematics at
    ``q`` (as :meth:`controllers.base.GuardedController.solve` leaves it).
    """

    def __init__(self, setup: StepSetup, data: pin.Data) -> None:
        if setup.tolerances != StepTolerances():
            raise ValueError("the Python step decides with the tolerances of "
                             "controllers/cjm/tolerances.py; a setup with others can only be "
                             "run by the compiled step")
        self.setup = setup
        self.data = data
        self._square_plans: dict[int, SquarePreChain] = {}
        self._active: list[int] = []
        self._equalities, self._barriers = setup.equalities, setup.barriers
        #: the step's collision rows (empty without collision avoidance), the ones held
        #: at their bound, and the bounds they are held at (in a conflict, what the
        #: equality rows leave them: docs/design.md section 18.4)
        self._pairs = CollisionRows.empty(setup.model.nv)
        self._active_pairs: list[int] = []
        self._pair_rhs = self._pairs.lower
        #: one task the analytical form may take (form auto, one EE, its full twist)
        self._analytical_task = setup.form == "auto" and setup.paper_task
        self._nq, self._task_size = setup.model.nq, setup.task_size
        #: the previous command, the acceleration limits' reference (zero at rest)
        self.previous = np.zeros(setup.model.nv)
        #: the box's reference when there are acceleration limits, else None
        self._reference = None if setup.bounds.acceleration_step is None else self.previous
        #: the previous command minus the one before, the jerk limits' reference
        self.previous_change = np.zeros(setup.model.nv)
        #: the box's change reference when there are jerk limits, else None
        self._change = None if setup.bounds.jerk_step is None else self.previous_change
        #: the acceleration limits the dampers brake with (None: none; docs/design.md 12)
        self._acceleration_limit = setup.bounds.acceleration_limit
        #: the warm start of the saturation around the previous command (docs/design.md
        #: 9.1): the last period's held joints' sides, its limiting joint, whether it was
        #: undamped and the command sent (None: none); this period's until it is sent
        self._held: tuple[np.ndarray, int, bool, np.ndarray] | None = None
        self._held_now: tuple[np.ndarray, int, bool] | None = None
        #: whether this period decided on the warm start already
        self._warm_tried = False
        self._run_report = StepReport()

    # -- the step template (controllers.base.GuardedController.solve) ------------------

    def solved_configuration(self) -> None:
        """None: this step computes its kinematics in the controller's ``data``, which is
        therefore at the configuration it last solved."""
        return None

    def solve(self, q: np.ndarray, twist: np.ndarray) -> tuple[np.ndarray, StepReport]:
        """``qd`` for the stacked EE twist at ``q`` and the step's report. Bad input
        raises ``ValueError``; a failed step gives the stop command (zero without
        acceleration limits, else the command nearest zero in the box)."""
        q, twist = checked_inputs(q, twist, self._nq, self._task_size)
        self._held_now, self._warm_tried = None, False
        qd, report = self._step(q, twist)
        self._held = None if self._held_now is None else (*self._held_now, qd.copy())
        np.subtract(qd, self.previous, out=self.previous_change)
        self.previous[:] = qd
        return qd, report

    def run(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """:meth:`solve`'s ``qd``; its report is :meth:`run_report`'s."""
        qd, self._run_report = self.solve(q, twist)
        return qd

    def run_report(self) -> StepReport:
        """The report of the last :meth:`run` (an ``ok`` one before any)."""
        return self._run_report

    def _step(self, q: np.ndarray, twist: np.ndarray) -> tuple[np.ndarray, StepReport]:
        setup = self.setup
        report = StepReport()
        ee_jacobian = self._kinematics(q)
        if setup.collisions is not None:
            self._pairs = report.collision = braked_pairs(
                setup.collisions.rows(setup.model, self.data), setup.collisions,
                self._acceleration_limit, setup.bounds.dt)
            self._pair_rhs = self._pairs.lower.copy()
        task = self._task(twist)
        try:
            warm = self._saturate_before_the_form(q, ee_jacobian, task, report)
        except np.linalg.LinAlgError as error:
            return self._fail(q, report, f"{type(error).__name__} while saturating: {error}")
        try:
            qd = warm[0] if warm is not None else self._solve(q, ee_jacobian, task, report)
        except np.linalg.LinAlgError as error:
            return self._fail(q, report, f"{type(error).__name__}: {error}")
        if warm is not None:
            qd = self._clip(qd, warm[1], warm[2], report)
            if not math.isfinite(sum(qd.tolist())):  # clipping passes a NaN through
                return self._fail(q, report, "", Event.NON_FINITE)
        elif not math.isfinite(sum(qd.tolist())):  # any NaN/inf (or overflow) poisons the sum
            return self._fail(q, report, "", Event.NON_FINITE)
        elif not setup.box_test.contains(q, qd, self._reference, self._change):
            lower, upper = setup.bounds.box(q, self._reference, self._change)
            try:
                qd = self._saturate(q, ee_jacobian, task, lower, upper, report)
            except np.linalg.LinAlgError as error:
                return self._fail(q, report, f"{type(error).__name__} while saturating: {error}")
            qd = self._clip(qd, lower, upper, report)
            if not math.isfinite(sum(qd.tolist())):  # clipping passes a NaN through
                return self._fail(q, report, "", Event.NON_FINITE)
        if report.equality_residual > EQUALITY_TOLERANCE:
            report.event(Event.RESIDUAL, StepStatus.CONSTRAINT_DEGRADED, report.equality_residual)
        report.active_pairs = tuple(self._active_pairs)
        return qd, report

    def _fail(self, q: np.ndarray, report: StepReport, error: str,
              event: Event = Event.LINEAR_ALGEBRA_ERROR) -> tuple[np.ndarray, StepReport]:
        report.fail(event, error)
        self._held_now = None
        return self.stop_command(q), report

    def stop_command(self, q: np.ndarray) -> np.ndarray:
        """The command nearest zero in the box (zero unless a joint past its limit must come
        back, or the acceleration limits cannot stop at once)."""
        lower, upper = self.setup.bounds.box(q, self._reference, self._change)
        return np.clip(0.0, lower, upper)

    def _kinematics(self, q: np.ndarray) -> np.ndarray:
        """The kinematics at ``q`` into ``data``; the task Jacobian ``W^1/2 J_e`` (the
        rows of non-zero weight of the stacked EE Jacobians)."""
        setup, data = self.setup, self.data
        model = setup.model
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        if len(setup.ee_frame_ids) == 1:
            jacobian = pin.getFrameJacobian(model, data, setup.ee_frame_ids[0], pin.LOCAL)
        else:
            jacobian = np.vstack([pin.getFrameJacobian(model, data, frame, pin.LOCAL)
                                  for frame in setup.ee_frame_ids])
        if setup.task_entries is None:
            return jacobian
        return setup.task_scale[:, None] * jacobian[setup.task_entries]

    def _task(self, twist: np.ndarray) -> np.ndarray:
        """``W^1/2 V_e``: the twist the weighted task Jacobian must meet."""
        setup = self.setup
        return twist if setup.task_entries is None else setup.task_scale * twist[setup.task_entries]

    def _clip(self, qd: np.ndarray, lower: np.ndarray, upper: np.ndarray,
              report: StepReport) -> np.ndarray:
        """The last guard: clip to the box; a change beyond rounding degrades the step."""
        clipped = np.clip(qd, lower, upper)
        change = float(np.max(np.abs(clipped - qd), initial=0.0))
        if change > EQUALITY_TOLERANCE * (1.0 + float(np.max(np.abs(qd), initial=0.0))):
            report.saturated_joints = tuple(np.flatnonzero(clipped != qd).tolist())
            report.event(Event.CLIPPED, StepStatus.CONSTRAINT_DEGRADED, change)
            rows, rhs = self.rows(self._equalities)
            if rows.shape[0]:
                report.equality_residual = float(np.max(np.abs(rows @ clipped - rhs)))
        return clipped

    def rows(self, indices: list[int] | tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """Stacked rows ``(A, b)`` of the chosen constraints at the kinematics in ``data``,
        a barrier's bound braking-aware with acceleration limits (docs/design.md 12)."""
        plans, model, data = self.setup.plans, self.setup.model, self.data
        blocks = [self._braked(i, *plans[i].constraint.rows(model, data, plans[i].frame_id))
                  for i in indices]
        if len(blocks) == 1:
            return blocks[0]
        if not blocks:
            return np.zeros((0, model.nv)), np.zeros(0)
        return np.vstack([A for A, _ in blocks]), np.concatenate([b for _, b in blocks])

    def _braked(self, index: int, rows: np.ndarray, rhs: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """Constraint ``index``'s rows, its bound :func:`braked_lower` if it is an
        inequality (a damper whose gap is its error) and there are acceleration limits."""
        constraint = self.setup.plans[index].constraint
        if self._acceleration_limit is None or constraint.is_equality:
            return rows, rhs
        gap = constraint.error(self.data.oMf[self.setup.plans[index].frame_id])
        return rows, braked_lower(rows, rhs, gap, np.array([constraint.gain]),
                                  self._acceleration_limit, self.setup.bounds.dt)

    # -- the forms and the barriers (docs/design.md sections 4-7) ------------------------

    def _solve(self, q: np.ndarray, ee_jacobian: np.ndarray, twist: np.ndarray,
               report: StepReport) -> np.ndarray:
        self._active = list(self._equalities)
        self._active_pairs = []
        qd = self._solve_rows(q, ee_jacobian, twist, self._active, report)
        if self._barriers or self._pairs.size:
            qd = self._activate(q, ee_jacobian, twist, qd, report)
        return qd

    def _activate(self, q: np.ndarray, ee_jacobian: np.ndarray, twist: np.ndarray,
                  qd: np.ndarray, report: StepReport) -> np.ndarray:
        """Active set over the barriers, then the collision rows: hold the most violated
        one as an equality, again (a barrier before any collision row)."""
        while self._activate_worst(qd):
            qd = self._solve_rows(q, ee_jacobian, twist, self._active, report)
        report.active_barriers = tuple(i for i in self._active if i in self._barriers)
        return qd

    def _activate_worst(self, qd: np.ndarray) -> bool:
        """Add the most violated waiting barrier, else the most violated waiting collision
        row, to the active set; False when none is violated."""
        waiting = [i for i in self._barriers if i not in self._active]
        if waiting:
            violations = [self._barrier_violation(i, qd) for i in waiting]
            worst = int(np.argmax(violations))
            if violations[worst] > 0.0:
                self._active.append(waiting[worst])
                return True
        waiting = [i for i in range(self._pairs.size) if i not in self._active_pairs]
        if waiting:
            rounding = 1.0 + np.abs(self._pairs.rows[waiting]) @ np.abs(qd)
            violations = self._pairs.violation(qd)[waiting] - BARRIER_TOLERANCE * rounding
            worst = int(np.argmax(violations))
            if violations[worst] > 0.0:
                self._active_pairs.append(waiting[worst])
                return True
        return False

    def _barrier_violation(self, index: int, qd: np.ndarray) -> float:
        """How far ``qd`` undercuts barrier ``index``'s row beyond the rounding of the
        product, ``BARRIER_TOLERANCE (1 + |a| . |qd|)``: at thousands of rad/s (a twist
        of 1e3) a row held as an equality is off by 1e-13 to 1e-12, and an absolute
        threshold decided on those bits (issue 32 item 6: a barrier on a plane's row
        active in one backend, not in the other, 0.021 rad/s apart)."""
        rows, rhs = self.rows([index])
        rounding = 1.0 + float(np.abs(rows[0]) @ np.abs(qd))
        return float(rhs[0] - rows[0] @ qd) - BARRIER_TOLERANCE * rounding

    def _held_rows(self, active: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """The rows held as equalities: the active constraints', then the active collision
        rows at their bounds (docs/design.md section 18.4)."""
        rows, rhs = self.rows(active)
        if not self._active_pairs:
            return rows, rhs
        pairs = self._active_pairs
        return (np.vstack([rows, self._pairs.rows[pairs]]),
                np.concatenate([rhs, self._pair_rhs[pairs]]))

    def _solve_rows(self, q: np.ndarray, ee_jacobian: np.ndarray, twist: np.ndarray,
                    active: list[int], report: StepReport) -> np.ndarray:
        """The analytical form where it applies, else the general form, for these rows."""
        setup = self.setup
        pairs = self._active_pairs
        if len(active) == 1 and self._analytical_task and not pairs and not (
                self._acceleration_limit is not None and active[0] in self._barriers):
            # (a braking-aware barrier's bound needs its joint-space row: the general form)
            qd = self._solve_analytical(q, ee_jacobian, twist, active[0], report)
            if qd is not None:
                return qd
        rows, rows_rhs = self._held_rows(active)
        qd = solve_general(rows, rows_rhs, ee_jacobian, twist, setup.policy,
                           self._posture_velocity(q), report, pairs)
        if pairs:  # the bounds a conflict set stay set for the rest of the step
            self._pair_rhs[pairs] = rows_rhs[len(rows_rhs) - len(pairs):]
        return qd

    def _solve_analytical(self, q: np.ndarray, ee_jacobian: np.ndarray, twist: np.ndarray,
                          index: int, report: StepReport) -> np.ndarray | None:
        """The analytical form of constraint ``index``, or None where it does not apply;
        the joints off the path to the EE take the posture velocity, as they do in the
        general form, where they lie in ``null(A)`` and ``null(J_e N)``."""
        qd = self._solve_analytical_path(q, ee_jacobian, twist, index, report)
        split = self.setup.plans[index].split
        if qd is not None and self.setup.posture_gain > 0.0 and split.off.size:
            qd[split.off] = self._posture_velocity(q)[split.off]
        return qd

    def _solve_analytical_path(self, q: np.ndarray, ee_jacobian: np.ndarray, twist: np.ndarray,
                               index: int, report: StepReport) -> np.ndarray | None:
        """The analytical form over the joints on the path to the EE (zero elsewhere)."""
        setup, data = self.setup, self.data
        plan = setup.plans[index]
        if setup.parametrisation == "paper" and not paper_form_defined(
                plan.constraint, data.oMf[plan.frame_id]):
            report.event(Event.PAPER_FORM_UNDEFINED)
            return None
        square = self._square_plans.get(index)  # the paper's case, seen before
        if square is None:
            if not plan.analytical:
                return None
            if plan.split.pre.size > 6:
                return solve_redundant_pre_chain(
                    setup.model, data, ee_jacobian, data.oMf[setup.ee_frame_ids[0]],
                    plan.constraint, plan.frame_id, plan.split, twist, setup.policy,
                    setup.parametrisation, self._posture_velocity(q), report)
            square = self._square_plans[index] = SquarePreChain(
                plan.constraint, plan.frame_id, setup.model.nv, plan.split, setup.parametrisation)
        return square.solve(setup.model, data, ee_jacobian, twist, setup.policy, report,
                            None if square.square else self._posture_velocity(q))

    def _posture_velocity(self, q: np.ndarray) -> np.ndarray | None:
        """``posture_gain (posture (-) q)``, zero on the joints the posture leaves alone
        (a mobile base: docs/design.md section 11.3); None at gain 0."""
        return None if self.setup.posture_gain == 0.0 else self.setup.posture_velocity(q)

    # -- joint limits (docs/design.md section 9) -----------------------------------------

    def _saturate(self, q: np.ndarray, ee_jacobian: np.ndarray, twist: np.ndarray,
                  lower: np.ndarray, upper: np.ndarray, report: StepReport) -> np.ndarray:
        """Saturation in the null space (module :mod:`controllers.cjm.saturation`), the
        barriers and the collision rows activated again against the saturated command."""
        setup = self.setup
        barriers = self._barriers
        for _ in range(len(barriers) + self._pairs.size + 1):
            rows, rows_rhs = self._held_rows(self._active)
            if self._reference is None:
                result = saturate_in_null_space(rows, rows_rhs, ee_jacobian, twist, lower,
                                                upper, setup.bounds.velocity_limit, setup.policy)
            else:
                warm = (None if self._warm_tried or not self._warm_start_applies() else
                        self._saturate_from_held(rows, rows_rhs, ee_jacobian, twist, lower,
                                                 upper, undamped_only=False))
                result = warm if warm is not None else saturate_around_previous(
                    rows, rows_rhs, ee_jacobian, twist, lower, upper, setup.policy,
                    self._reference)
            if not self._activate_worst(result.qd):
                break
        report.active_barriers = tuple(i for i in self._active if i in barriers)
        return self._report_saturation(result, rows, rows_rhs, lower, upper, report)

    def _warm_start_applies(self) -> bool:
        """Whether the last period left a warm start this period may take: the previous
        command still the one it sent, the equalities alone as the rows (no barrier, no
        collision row)."""
        return (self._held is not None and not self._barriers and not self._pairs.size
                and np.array_equal(self.previous, self._held[3]))

    def _saturate_before_the_form(self, q: np.ndarray, ee_jacobian: np.ndarray,
                                  twist: np.ndarray, report: StepReport
                                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The warm start in place of the unsaturated form (docs/design.md 9.1): where the
        last period's saturation held a joint and was undamped, and this period's is
        undamped too; the command and the box, or None."""
        held = self._held
        if held is None or not held[0].any() or not held[2] or not self._warm_start_applies():
            return None
        self._active, self._active_pairs = list(self._equalities), []
        lower, upper = self.setup.bounds.box(q, self._reference, self._change)
        rows, rows_rhs = self._held_rows(self._active)
        result = self._saturate_from_held(rows, rows_rhs, ee_jacobian, twist, lower, upper,
                                          undamped_only=True)
        if result is None:
            return None
        plans = self.setup.plans
        if (self.setup.parametrisation == "paper" and len(plans) == 1 and self._analytical_task
                and not paper_form_defined(plans[0].constraint, self.data.oMf[plans[0].frame_id])):
            report.event(Event.PAPER_FORM_UNDEFINED)  # as the compiled step records it
        return self._report_saturation(result, rows, rows_rhs, lower, upper, report), lower, upper

    def _saturate_from_held(self, rows: np.ndarray, rows_rhs: np.ndarray,
                            ee_jacobian: np.ndarray, twist: np.ndarray, lower: np.ndarray,
                            upper: np.ndarray, undamped_only: bool) -> Saturation | None:
        """:func:`controllers.cjm.saturation_walk.saturate_from_held` with the last
        period's held joints; whether it decided is kept for the rest of the period."""
        assert self._held is not None
        sides, limiting_joint = self._held[:2]
        result, decided = saturate_from_held(rows, rows_rhs, ee_jacobian, twist, lower, upper,
                                             self.setup.policy, sides, limiting_joint,
                                             undamped_only)
        self._warm_tried = self._warm_tried or decided
        return result

    def _report_saturation(self, result: Saturation, rows: np.ndarray, rows_rhs: np.ndarray,
                           lower: np.ndarray, upper: np.ndarray, report: StepReport) -> np.ndarray:
        """``result``'s command and its report; around the previous command, its held
        joints kept for the next period's warm start."""
        if self._reference is not None:
            sides = held_sides(result, lower, upper)
            self._held_now = (None if sides is None else
                              (sides, result.limiting_joint, result.damping == 0.0))
        report.method = "saturated"
        report.scale = result.task_scale
        report.saturated_joints = result.saturated
        if not math.isnan(result.sigma_min):  # the task's DLS that gave this command
            report.sigma_min, report.damping = result.sigma_min, result.damping
        report.equality_residual = (float(np.max(np.abs(rows @ result.qd - rows_rhs)))
                                    if rows.shape[0] else 0.0)
        if result.rows_scale < 1.0:
            report.event(Event.ROWS_SCALED, StepStatus.CONSTRAINT_DEGRADED, result.rows_scale)
        elif result.task_missed:
            report.saturation_joints = result.saturated
            report.event(Event.TASK_MISSED, StepStatus.LEAST_SQUARES, result.sigma_min,
                         result.damping)
        elif result.task_scale < 1.0:
            report.event(Event.TASK_SCALED, StepStatus.SCALED, result.limiting_joint,
                         result.task_scale)
        return result.qd


def paper_form_defined(constraint, placement: pin.SE3) -> bool:
    """Whether the paper's ``1/a`` structure matrix exists at this placement of the
    constraint's link (``a = |p|`` not ~0)."""
    return float(np.linalg.norm(constraint.point(placement))) >= PAPER_FORM_MIN_A
