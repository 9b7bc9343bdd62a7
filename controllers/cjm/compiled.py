"""The compiled CJM step (docs/design.md section 16).

Pinocchio's kinematics and each constraint's terms stay in Python (a few calls per
constraint); the dense algebra of the whole step (the analytical form, the general form,
the barriers' active set, saturation in the null space, the clip guard and the status)
is one call into the C++ extension ``controllers.cjm._step`` (Eigen only), which
releases the GIL and allocates nothing. It runs the algorithms of :mod:`.analytical`,
:mod:`.general`, :mod:`.saturation` and :class:`.controller.CJMController`, which stay
the readable reference (``backend="python"``); tests/test_compiled_step.py holds the two
equal.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from ..base import NON_FINITE_NOTE, SolveInfo, SolverError, StepStatus, clipped_note, residual_note
from ..linalg import DampingPolicy
from . import _step
from .analytical import PRE_CHAIN_SINGULAR_NOTE, TermsWriter, terms_size, task_residual_note
from .general import NO_FREE_JOINT_NOTE, conflict_note
from .saturation import rows_scaled_note

if TYPE_CHECKING:
    from .controller import CJMController

#: SolveInfo.method by the C++ code (0: none yet)
METHODS = ("", "analytical", "general", "saturated")
#: StepStatus by the C++ code (the enum's order, best to worst)
STATUSES = tuple(StepStatus)
FIELD = _step.REPORT_FIELDS
EVENT = _step.EVENTS
#: the message of a step whose SVD did not converge (the command is zero)
NO_CONVERGENCE_NOTE = "LinAlgError: SVD did not converge (Jacobi sweeps)"
#: the paper's 1/a form undefined: the note of CJMController._solve_analytical
PAPER_FORM_NOTE = "a = 0, where the paper's 1/a form is singular: null-space form used"


class CompiledStep:
    """One :class:`CJMController`'s compiled step: buffers allocated once, one C++ call a
    step. Built by the controller's ``_prepare`` (so again for new constraints)."""

    def __init__(self, controller: CJMController) -> None:
        model = controller.model
        self._controller = controller
        constraints = controller.constraints
        self._single = len(constraints) == 1
        # the paper's S only where the analytical form can use it (one hole, form auto)
        self._paper = (controller.parametrisation == "paper" and self._single
                       and controller.form == "auto")
        self._writers = [TermsWriter(c, "paper" if self._paper else "nullspace")
                         for c in constraints]
        self._fallback_writer = TermsWriter(constraints[0], "nullspace") if self._paper else None
        sizes = [terms_size(c.dim) for c in constraints]
        self._terms = np.empty(sum(sizes))
        offsets = np.cumsum([0] + sizes)
        self._terms_views = [self._terms[offsets[i]:offsets[i + 1]] for i in range(len(sizes))]
        self._frame_jacobians = np.zeros((6 * len(constraints), model.nv))
        self._posture = np.zeros(model.nv)
        self._use_posture = controller.posture_gain > 0.0
        one_coordinate = all(model.nqs[j] == 1 and model.nvs[j] == 1 for j in range(1, model.njoints))
        self._posture_in_python = self._use_posture and not one_coordinate
        plans = []
        for constraint, frame in zip(constraints, controller.constraint_frames):
            split = controller.split(frame)
            analytical = controller.paper_task and split is not None and split.pre.size >= 6
            plans.append(_step.ConstraintPlan(
                rows=constraint.dim, equality=constraint.is_equality, analytical=analytical,
                pre=split.pre.tolist() if analytical else [],
                post=split.post.tolist() if analytical else []))
        bounds = controller.joint_bounds
        velocity_box = bounds._velocity_box  # the box's parts, as JointBounds.box uses them
        box = _step.JointBox(
            velocity_lower=velocity_box[0], velocity_upper=velocity_box[1],
            velocity_limit=bounds.velocity_limit, limited_q=bounds._limited_q.tolist(),
            limited_v=bounds._limited_v.tolist(), q_min=bounds._q_limits[0],
            q_max=bounds._q_limits[1], position_gain=bounds.limit_gain / bounds.dt,
            position_limits=bounds.position_limits, box_test=controller._box_test._matrix)
        policy = controller.policy
        self._policy = policy
        self._step = _step.Step(
            nq=model.nq, nv=model.nv, task_rows=controller.task_rows, damping=policy.damping,
            threshold=policy.threshold, max_damping=policy.max_damping,
            general_only=controller.form == "general", constraints=plans, box=box,
            posture_gain=controller.posture_gain,
            posture_target=(controller.posture if one_coordinate and self._use_posture
                            else np.zeros(0)))
        self._report = self._step.report
        self._events = self._step.events
        self._saturated = self._step.saturated_joints
        self._active_barriers = self._step.active_barriers
        self._saturation_joints = self._step.saturation_joints
        self._frames = list(zip(controller.constraint_frames, self._writers, self._terms_views,
                                range(len(constraints))))

    def _set_policy(self, policy: DampingPolicy) -> None:
        self._step.set_policy(policy.damping, policy.threshold, policy.max_damping)
        self._policy = policy

    def solve(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """``qd`` for checked inputs; sets ``controller.info`` (section 8.3)."""
        controller = self._controller
        model, data = controller.model, controller.data
        if controller.policy is not self._policy:  # e.g. the UI's damping slider
            self._set_policy(controller.policy)
        pin.computeJointJacobians(model, data, q)
        ee_jacobian = controller._task_jacobian(controller._ee_jacobian())
        frame_jacobians = self._frame_jacobians
        analytical_allowed, note = True, ""
        for frame, writer, terms, i in self._frames:
            placement = pin.updateFramePlacement(model, data, frame)
            jacobian = pin.getFrameJacobian(model, data, frame, pin.LOCAL)
            if self._single:
                frame_jacobians = jacobian
            else:
                frame_jacobians[6 * i:6 * i + 6] = jacobian
            if self._paper and not controller._paper_form_defined(0):
                analytical_allowed, note = False, PAPER_FORM_NOTE
                writer = self._fallback_writer
            writer.write(placement, terms)
        if self._posture_in_python:
            np.multiply(controller.posture_gain,
                        controller.posture_difference(q, controller.posture), out=self._posture)
        qd = np.empty(model.nv)
        self._step.solve(q, controller._task(twist), ee_jacobian, frame_jacobians, self._terms,
                         self._posture, self._use_posture, analytical_allowed, qd)
        info = controller.info = self._info(note)
        if info.status is StepStatus.FAILED and controller.strict:
            raise SolverError(info.message)
        return qd

    def _info(self, note: str) -> SolveInfo:
        """SolveInfo from the C++ report; the events, in order, give the message."""
        report = self._report.tolist()
        saturated = int(report[FIELD["saturated_count"]])
        barriers = int(report[FIELD["active_barrier_count"]])
        info = SolveInfo(
            method=METHODS[int(report[FIELD["method"]])], sigma_min=report[FIELD["sigma_min"]],
            damping=report[FIELD["damping"]], scale=report[FIELD["scale"]],
            saturated_joints=tuple(self._saturated[:saturated].tolist()) if saturated else (),
            active_barriers=tuple(self._active_barriers[:barriers].tolist()) if barriers else (),
            equality_residual=report[FIELD["equality_residual"]])
        if note:
            info.report(StepStatus.OK, note)
        events = int(report[FIELD["event_count"]])
        if events:
            self._replay(info, self._events[:events].tolist(),
                         self._saturation_joints[:int(report[FIELD["saturation_joint_count"]])].tolist())
        info.status = STATUSES[int(report[FIELD["status"]])]
        return info

    def _replay(self, info: SolveInfo, events: list[list[float]], saturation_joints: list[int]) -> None:
        """The notes of the Python step, from the C++ events (status set by the caller)."""
        controller = self._controller
        for code, a, b, c in events:
            event = int(code)
            if event == EVENT["pre_chain_singular"]:
                info.message = PRE_CHAIN_SINGULAR_NOTE
            elif event == EVENT["task_residual"]:
                info.report(StepStatus.LEAST_SQUARES, task_residual_note(a, b))
            elif event == EVENT["conflict"]:
                info.report(StepStatus.CONSTRAINT_DEGRADED, conflict_note(int(a), int(b), c))
            elif event == EVENT["no_free_joint"]:
                info.report(StepStatus.LEAST_SQUARES, NO_FREE_JOINT_NOTE)
            elif event == EVENT["rows_scaled"]:
                info.report(StepStatus.CONSTRAINT_DEGRADED, rows_scaled_note(a))
            elif event == EVENT["task_missed"]:
                info.report(StepStatus.LEAST_SQUARES, controller._task_missed_note(saturation_joints))
            elif event == EVENT["task_scaled"]:
                info.report(StepStatus.SCALED, controller._task_scaled_note(int(a), b))
            elif event == EVENT["clipped"]:
                info.report(StepStatus.CONSTRAINT_DEGRADED,
                            clipped_note(list(info.saturated_joints), a))
            elif event == EVENT["residual"]:
                info.report(StepStatus.CONSTRAINT_DEGRADED, residual_note(a))
            elif event == EVENT["no_convergence"]:
                info.status, info.message = StepStatus.FAILED, NO_CONVERGENCE_NOTE
            elif event == EVENT["non_finite"]:
                info.status, info.message = StepStatus.FAILED, NON_FINITE_NOTE
