"""The compiled CJM step (docs/design.md section 16).

The whole step is C++ (the extension ``controllers.cjm._step``): Pinocchio's kinematics
(its templates compiled in, the model copied from ``controller.model``), the terms of
the constraints with an affine form (a hole), the analytical form, the general form, the
barriers' active set, saturation in the null space, the clip guard and the status. It
releases the GIL and allocates nothing but the returned ``qd``. When every constraint has
an affine form a step is one call; otherwise Python writes the other constraints' terms
from the link placements the C++ kinematics gives, between two calls. It runs the
algorithms of :mod:`.analytical`, :mod:`.general`, :mod:`.saturation` and
:class:`.controller.CJMController`, which stay the readable reference
(``backend="python"``); tests/test_compiled_step.py holds the two equal.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from constraints import Constraint

from ..base import NON_FINITE_NOTE, SolveInfo, SolverError, StepStatus, clipped_note, residual_note
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
EVENT = _step.EVENTS
#: the C++ report's entries, in the order CompiledStep._info unpacks them
REPORT_FIELDS = ("status", "method", "sigma_min", "damping", "scale", "equality_residual",
                 "saturated_count", "active_barrier_count", "event_count",
                 "saturation_joint_count")
if tuple(sorted(_step.REPORT_FIELDS, key=_step.REPORT_FIELDS.get)) != REPORT_FIELDS:
    raise ImportError("controllers.cjm._step reports other fields: rebuild it (pip install -e .)")
#: the message of a step whose SVD did not converge (the command is zero)
NO_CONVERGENCE_NOTE = "LinAlgError: SVD did not converge (Jacobi sweeps)"
#: the paper's 1/a form undefined: the note of CJMController._solve_analytical
PAPER_FORM_NOTE = "a = 0, where the paper's 1/a form is singular: null-space form used"


#: largest difference (m, or 1 for rotations and Jacobians) the copy of the model may
#: show against Pinocchio's Python kinematics when it is built
KINEMATICS_TOLERANCE = 1e-9


class KinematicsMismatch(ValueError):
    """The C++ copy of the model does not reproduce Pinocchio's kinematics."""


def joint_specs(model: pin.Model) -> list[tuple[str, int, np.ndarray, np.ndarray]]:
    """``(kind, parent, placement, axis)`` of each joint after the universe, for the C++
    copy of the model (``axis``: an unaligned joint's, else zero)."""
    specs = []
    for j in range(1, model.njoints):
        joint = model.joints[j]
        kind = joint.shortname()
        axis = unaligned_axis(joint) if kind.endswith("Unaligned") else np.zeros(3)
        specs.append((kind, model.parents[j], model.jointPlacements[j].homogeneous, axis))
    return specs


def unaligned_axis(joint: pin.JointModel) -> np.ndarray:
    """A one-degree-of-freedom joint's axis, exactly: its motion subspace, the Jacobian of
    a model of that joint alone at its neutral configuration (Python does not expose the
    axis of every kind)."""
    alone = pin.Model()
    alone.addJoint(0, joint, pin.SE3.Identity(), "alone")
    data = alone.createData()
    pin.computeJointJacobians(alone, data, pin.neutral(alone))
    column = np.asarray(data.J).reshape(6, -1)[:, 0]
    return column[:3].copy() if "Prismatic" in joint.shortname() else column[3:].copy()


@dataclass
class AffineEntry:
    """A constraint whose terms the C++ side computes, and what it was last sent."""

    index: int
    constraint: Constraint
    writer: TermsWriter
    sent_anchor: np.ndarray | None = None
    sent_gain: float | None = None


class CompiledStep:
    """One :class:`CJMController`'s compiled step: buffers allocated once, one C++ call a
    step when every constraint has an affine form. Built by the controller's
    ``_prepare`` (so again for new constraints)."""

    def __init__(self, controller: CJMController) -> None:
        model = controller.model
        self._controller = controller
        constraints = controller.constraints
        # the paper's S only where the analytical form can use it (one hole, form auto)
        self._paper = (controller.parametrisation == "paper" and len(constraints) == 1
                       and controller.form == "auto" and controller.paper_task)
        writers = [TermsWriter(c, "paper" if self._paper else "nullspace") for c in constraints]
        self._fallback_writer = TermsWriter(constraints[0], "nullspace") if self._paper else None
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
        policy = self._policy = controller.policy
        step = _step.Step(
            nq=model.nq, nv=model.nv, task_rows=controller.task_rows, damping=policy.damping,
            threshold=policy.threshold, max_damping=policy.max_damping,
            general_only=controller.form == "general", constraints=plans, box=box,
            posture_gain=controller.posture_gain,
            posture_target=(controller.posture if one_coordinate and self._use_posture
                            else np.zeros(0)))
        frames = [*controller.ee_frame_ids, *controller.constraint_frames]
        task_entries = (np.arange(controller.task_size) if controller._task_rows is None
                        else controller._task_rows)
        self._pipeline = _step.Pipeline(
            joints=joint_specs(model),
            frames=[(model.frames[f].parentJoint, model.frames[f].placement.homogeneous)
                    for f in frames],
            step=step, ee_count=len(controller.ee_frame_ids), task_entries=task_entries.tolist(),
            task_scale=controller._task_row_scale[:, 0])
        pipeline = self._pipeline
        step = pipeline.step
        self._report = step.report
        self._events = step.events
        self._saturated = step.saturated_joints
        self._active_barriers = step.active_barriers
        self._saturation_joints = step.saturation_joints
        terms, placements = pipeline.terms, pipeline.placements
        offsets = np.cumsum([0] + [terms_size(c.dim) for c in constraints])
        self._affine: list[AffineEntry] = []
        #: (writer, terms view, link rotation and translation views) of the others
        self._in_python: list[tuple[TermsWriter, np.ndarray, np.ndarray, np.ndarray]] = []
        for i, writer in enumerate(writers):
            row = placements[len(controller.ee_frame_ids) + i]
            if writer.affine:
                self._affine.append(AffineEntry(i, writer.constraint, writer))
            else:
                self._in_python.append((writer, terms[offsets[i]:offsets[i + 1]],
                                        row[:9].reshape(3, 3), row[9:]))
        self._one_call = not self._in_python and not self._posture_in_python
        self._check_kinematics(frames)

    def _check_kinematics(self, frames: list[int]) -> None:
        """The copy of the model against Pinocchio, once, at the posture: a joint it
        reproduces wrongly raises :class:`KinematicsMismatch` (a safety net under the
        tests of tests/test_compiled_kinematics.py)."""
        controller, pipeline = self._controller, self._pipeline
        model, data = controller.model, controller.model.createData()
        pipeline.load(controller.posture, np.zeros(controller.task_size))
        pipeline.prepare()
        pin.computeJointJacobians(model, data, controller.posture)
        for i, frame in enumerate(frames):
            placement = pin.updateFramePlacement(model, data, frame)
            expected = np.concatenate([placement.rotation.ravel(), placement.translation])
            jacobian = pin.getFrameJacobian(model, data, frame, pin.LOCAL)
            difference = max(np.abs(pipeline.placements[i] - expected).max(),
                             np.abs(pipeline.jacobians[6 * i:6 * i + 6] - jacobian).max())
            if not difference <= KINEMATICS_TOLERANCE:
                raise KinematicsMismatch(
                    f"the compiled step's kinematics differ from Pinocchio's by {difference:.3g} "
                    f"at frame {model.frames[frame].name!r}: use backend='python'")

    def solve(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """``qd`` (section 8.3): bad input raises ValueError as :meth:`Controller.solve`
        does; sets ``controller.info``."""
        controller = self._controller
        pipeline = self._pipeline
        if controller.policy is not self._policy:  # e.g. the UI's damping slider
            policy = self._policy = controller.policy
            pipeline.set_policy(policy.damping, policy.threshold, policy.max_damping)
        for entry in self._affine:
            constraint = entry.constraint
            anchor = constraint.affine_anchor()
            if anchor is not entry.sent_anchor or constraint.gain != entry.sent_gain:
                self._send_anchor(entry, anchor)
        if self._one_call:
            qd = pipeline.solve(q, twist, self._use_posture, True)
            if qd is None:  # not finite float vectors of the right sizes: say what is wrong
                qd = pipeline.solve(*controller._checked_inputs(q, twist), self._use_posture, True)
            note = ""
        else:
            if not pipeline.load(q, twist):
                pipeline.load(*controller._checked_inputs(q, twist))
            pipeline.prepare()
            analytical_allowed, note = self._write_in_python()
            qd = pipeline.finish(self._use_posture, analytical_allowed)
        info = controller.info = self._info(note)
        if info.status is StepStatus.FAILED and controller.strict:
            raise SolverError(info.message)
        return qd

    def _send_anchor(self, entry: AffineEntry, anchor: np.ndarray) -> None:
        """A new anchor of an affine constraint into the C++ buffer, and its affine map
        when its gain changed (a new anchor array is a moved constraint)."""
        constraint = entry.constraint
        self._pipeline.anchors[entry.index] = anchor
        if constraint.gain != entry.sent_gain:
            terms = entry.writer.affine_terms()
            self._pipeline.set_affine(entry.index, terms.of_x, terms.of_f, terms.offset)
        entry.sent_anchor, entry.sent_gain = anchor, constraint.gain

    def _write_in_python(self) -> tuple[bool, str]:
        """The terms of the constraints without an affine form, and a posture velocity
        Python computes; returns whether the analytical form may run, and a note."""
        controller = self._controller
        analytical_allowed, note = True, ""
        for writer, terms, rotation, translation in self._in_python:
            placement = pin.SE3(rotation, translation)
            if self._paper and not controller._paper_form_defined(0, placement):
                analytical_allowed, note = False, PAPER_FORM_NOTE
                writer = self._fallback_writer
            writer.write(placement, terms)
        if self._posture_in_python:
            np.multiply(controller.posture_gain,
                        controller.posture_difference(self._pipeline.q, controller.posture),
                        out=self._pipeline.posture)
        return analytical_allowed, note

    def _info(self, note: str) -> SolveInfo:
        """SolveInfo from the C++ report; the events, in order, give the message."""
        (status, method, sigma_min, damping, scale, equality_residual, saturated, barriers,
         events, saturation_joints) = self._report.tolist()
        info = SolveInfo(
            method=METHODS[int(method)], sigma_min=sigma_min, damping=damping, scale=scale,
            saturated_joints=tuple(self._saturated[:int(saturated)].tolist()) if saturated else (),
            active_barriers=(tuple(self._active_barriers[:int(barriers)].tolist())
                             if barriers else ()),
            equality_residual=equality_residual)
        if note:
            info.report(StepStatus.OK, note)
        if events:
            self._replay(info, self._events[:int(events)].tolist(),
                         self._saturation_joints[:int(saturation_joints)].tolist())
        info.status = STATUSES[int(status)]
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
                info.report(StepStatus.LEAST_SQUARES,
                            controller._task_missed_note(saturation_joints, a, b))
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
