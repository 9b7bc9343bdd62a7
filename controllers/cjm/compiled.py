"""The compiled CJM step: a thin wrapper over the C++ extension (docs/design.md section 16).

:class:`CompiledStep` takes a :class:`~controllers.cjm.step_setup.StepSetup`, hands it
to ``controllers.cjm._step`` once (the tolerances included), and then runs
``solve(q, twist) -> (qd, report)`` as the Python reference
(:class:`~controllers.cjm.python_step.PythonStep`) does: one C++ call a step for any mix of
holes (both parametrisations), planes, barriers and point locks, whose terms the C++ side
computes from its type's registered form (:mod:`controllers.cjm.compiled_forms`, its
parameters taken again only when the constraint's ``revision`` is replaced). A constraint
type without a compiled form (a user's own) has its terms written by Python between two
calls.
tests/test_compiled_step.py and tests/test_cjm_backends_fuzz.py hold the two equal.

With collision avoidance (docs/design.md section 18.4) the C++ pipeline measures the
avoidance rows right after its kinematics and writes them into the step's buffer (its
capacity: the number of pairs when built, grown if obstacles add pairs;
:mod:`controllers.cjm.compiled_collisions`), one C++ call a step as without them; the C++
active set holds them as the Python step does. A robot body that is not a primitive (a
mesh's convex hull) leaves the rows to Python: it computes Pinocchio's joint Jacobians on
the controller's ``data`` and the rows there, and writes them into the buffer.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin

from constraints.collision import CollisionRows

from ..base import StepStatus, checked_inputs
from ..joint_acceleration import DAMPER_BRAKING_SHARE, braked_pairs
from . import _step
from ._step import JointBox, Pipeline, Report, Step, Tolerances
from ._step import ConstraintPlan as CompiledPlan
from .compiled_forms import UNIT_TOLERANCE, compiled_form_of
from .analytical import TermsWriter, terms_size
from .compiled_collisions import CompiledCollisions
from .python_step import paper_form_defined
from .pose_rows import row_views
from .report import EVENT_BY_CODE, METHODS, Event, StepReport, code_mismatches
from .step_setup import StepSetup
from .tolerances import PAPER_FORM_MIN_A

#: StepStatus by the C++ code (the enum's order, best to worst)
STATUSES = tuple(StepStatus)
# the C++ codes (_step/report.hpp) are the ones controllers.cjm.report reads
_MISMATCHES = code_mismatches(*(getattr(_step, name, {}) for name in
                                ("EVENTS", "STATUSES", "METHODS")))
if _MISMATCHES:
    raise ImportError("controllers.cjm._step's codes are not controllers.cjm.report's: "
                      f"{'; '.join(_MISMATCHES)} (rebuild it: pip install -e .)")

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


def joint_box(setup: StepSetup) -> JointBox:
    """The joint box of ``setup.bounds`` (and its fast test) for the C++ step."""
    bounds = setup.bounds
    return JointBox(
        velocity_lower=bounds.velocity_box[0], velocity_upper=bounds.velocity_box[1],
        velocity_limit=bounds.velocity_limit, limited_q=bounds.limited_q.tolist(),
        limited_v=bounds.limited_v.tolist(), q_min=bounds.q_limits[0], q_max=bounds.q_limits[1],
        position_gain=bounds.limit_gain / bounds.dt, position_limits=bounds.position_limits,
        box_test=setup.box_test.matrix,
        acceleration_step=(np.zeros(0) if bounds.acceleration_step is None
                           else bounds.acceleration_step),
        dt=bounds.dt, limit_gain=bounds.limit_gain, slack=setup.box_test.slack,
        damper_step=(np.zeros(0) if bounds.acceleration_step is None
                     else DAMPER_BRAKING_SHARE * bounds.acceleration_step),
        jerk_step=np.zeros(0) if bounds.jerk_step is None else bounds.jerk_step)


class CompiledStep:
    """One controller's compiled step: ``solve(q, twist) -> (qd, report)``, buffers
    allocated once. Raises :class:`KinematicsMismatch` when the C++ copy of the model
    does not reproduce Pinocchio's kinematics. ``data``: the controller's, where the
    collision rows are measured (needed with ``setup.collisions`` only);
    ``pair_capacity``: the collision rows the C++ step can take (default: every pair);
    ``event_capacity``: the events a step records (default: eight per constraint, 16 more
    and one per collision row), those past it counted in the report's
    ``dropped_events``."""

    def __init__(self, setup: StepSetup, data: pin.Data | None = None,
                 pair_capacity: int | None = None, event_capacity: int | None = None) -> None:
        self.setup = setup
        self.data = data
        self._event_capacity = event_capacity
        self._collisions = setup.collisions
        if self._collisions is not None and data is None:
            raise ValueError("a compiled step with collision avoidance needs the controller's data")
        if pair_capacity is None:
            pair_capacity = 0 if self._collisions is None else len(self._collisions.pairs)
        model = setup.model
        plans = setup.plans
        # the paper's S only where the analytical form can use it (one hole, form auto)
        self._paper = (setup.parametrisation == "paper" and len(plans) == 1
                       and setup.form == "auto" and setup.paper_task)
        self._fallback_writer = TermsWriter(plans[0].constraint, "nullspace") if self._paper else None
        self._use_posture = setup.posture_gain > 0.0
        one_coordinate = all(model.nqs[j] == 1 and model.nvs[j] == 1 for j in range(1, model.njoints))
        self._posture_in_python = self._use_posture and not one_coordinate
        policy = setup.policy
        step = Step(
            nq=model.nq, nv=model.nv, task_rows=setup.task_rows, damping=policy.damping,
            threshold=policy.threshold, max_damping=policy.max_damping,
            general_only=setup.form == "general",
            constraints=[CompiledPlan(
                rows=plan.constraint.dim, equality=plan.constraint.is_equality,
                analytical=plan.analytical, pre=plan.split.pre.tolist() if plan.analytical else [],
                post=plan.split.post.tolist() if plan.analytical else []) for plan in plans],
            box=joint_box(setup), posture_gain=setup.posture_gain,
            posture_target=setup.posture if one_coordinate and self._use_posture else np.zeros(0),
            tolerances=Tolerances(**dataclasses.asdict(setup.tolerances)),
            pair_capacity=pair_capacity,
            event_capacity=-1 if event_capacity is None else event_capacity)
        frames = [*setup.ee_frame_ids, *(plan.frame_id for plan in plans)]
        task_entries = (np.arange(setup.task_size) if setup.task_entries is None
                        else setup.task_entries)
        #: the C++ pipeline (kinematics, terms and step)
        self.pipeline = pipeline = Pipeline(
            joints=joint_specs(model),
            frames=[(model.frames[f].parentJoint, model.frames[f].placement.homogeneous)
                    for f in frames],
            step=step, ee_count=len(setup.ee_frame_ids), task_entries=task_entries.tolist(),
            task_scale=setup.task_scale)
        step = pipeline.step
        self._events = step.events
        self._saturated = step.saturated_joints
        self._active_barriers = step.active_barriers
        self._saturation_joints = step.saturation_joints
        self._step = step
        self._pair_rows, self._pair_lower = step.pair_rows, step.pair_lower
        self._active_pairs = step.active_pairs
        terms, placements = pipeline.terms, pipeline.placements
        offsets = np.cumsum([0] + [terms_size(plan.constraint.dim) for plan in plans])
        #: (index, writer, terms view, link rotation and translation views) of the
        #: constraints that declare no compiled form: Python writes their terms (and an
        #: inequality's damper gap and gain, docs/design.md 12)
        self._in_python: list[tuple[int, TermsWriter, np.ndarray, np.ndarray, np.ndarray]] = []
        for i, plan in enumerate(plans):
            constraint = plan.constraint
            form = compiled_form_of(constraint)
            if form is not None:
                pipeline.declare(i, constraint, form.kind, form.values, self._paper,
                                 PAPER_FORM_MIN_A, UNIT_TOLERANCE)
            else:
                row = placements[len(setup.ee_frame_ids) + i]
                writer = TermsWriter(constraint, "paper" if self._paper else "nullspace")
                self._in_python.append((i, writer, terms[offsets[i]:offsets[i + 1]],
                                        *row_views(row)))
        self._one_call = not self._in_python and not self._posture_in_python
        #: the previous command, the acceleration limits' reference (a view of the C++ step's)
        self.previous = step.previous
        #: the previous command minus the one before, the jerk limits' (a view, the same)
        self.previous_change = step.previous_change
        self._check_kinematics(frames)
        #: the collision rows measured in C++ (None without collision avoidance)
        self.collision_rows = (None if self._collisions is None
                               else CompiledCollisions(pipeline, self._collisions))
        #: the last :meth:`run`'s report, None until :meth:`run_report` builds it
        self._run_report: StepReport | None = StepReport()
        self._run_paper_form = True

    def _check_kinematics(self, frames: list[int]) -> None:
        """The copy of the model against Pinocchio, once, at the posture: a joint it
        reproduces wrongly raises :class:`KinematicsMismatch` (a safety net under the
        tests of tests/test_compiled_kinematics.py)."""
        setup, pipeline = self.setup, self.pipeline
        model = setup.model
        data = model.createData()
        pipeline.load(setup.posture, np.zeros(setup.task_size))
        pipeline.prepare()
        pin.computeJointJacobians(model, data, setup.posture)
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

    def solved_configuration(self) -> np.ndarray:
        """The configuration the pipeline last loaded (its kinematics are on its own copy
        of the model, not in the controller's ``data``)."""
        return self.pipeline.q.copy()

    def solve(self, q: np.ndarray, twist: np.ndarray) -> tuple[np.ndarray, StepReport]:
        """``qd`` for the stacked EE twist at ``q`` and the step's report (section 8.3);
        bad input raises ``ValueError`` as the Python step does."""
        self.run_report()
        if self._collisions is not None:
            return self._solve_with_pairs(q, twist)
        qd, paper_form = self._run(q, twist)
        return qd, self.last_report(paper_form)

    def run(self, q: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """:meth:`solve`'s ``qd``, its report built by :meth:`run_report` when read
        (docs/design.md 16: a report nobody reads costs nothing; with collision avoidance
        it is built now, around the rows of the step)."""
        if self._collisions is not None:
            qd, self._run_report = self._solve_with_pairs(q, twist)
            return qd
        qd, self._run_paper_form = self._run(q, twist)
        self._run_report = None
        return qd

    def run_report(self) -> StepReport:
        """The report of the last :meth:`run` (an ``ok`` one before any), built from the
        C++ report on the first read; a call that runs the pipeline otherwise
        (:meth:`solve`, :meth:`time_steps`) builds it first."""
        report = self._run_report
        if report is None:
            report = self._run_report = self.last_report(self._run_paper_form)
        return report

    def _run(self, q: np.ndarray, twist: np.ndarray) -> tuple[np.ndarray, bool]:
        """The pipeline's step at ``q``: one C++ call, or two around the terms Python
        writes; returns ``qd`` and whether the paper's form was defined."""
        pipeline = self.pipeline
        if self._one_call:
            qd = pipeline.solve(q, twist, self._use_posture, True)
            if qd is None:  # not finite float vectors of the right sizes: say what is wrong
                qd = pipeline.solve(*self._checked(q, twist), self._use_posture, True)
            return qd, not self._paper or pipeline.paper_form
        if not pipeline.load(q, twist):
            pipeline.load(*self._checked(q, twist))
        pipeline.prepare()
        paper_form = self._write_in_python() and pipeline.paper_form
        return pipeline.finish(self._use_posture, paper_form), paper_form

    def _solve_with_pairs(self, q: np.ndarray, twist: np.ndarray) -> tuple[np.ndarray, StepReport]:
        """The step with the collision rows at ``q``, measured by the C++ pipeline (or by
        Python, :meth:`_write_python_pairs`, for shapes it does not cover); the report
        carries the rows and the pairs held. Bad input raises ``ValueError`` as
        :meth:`solve` does."""
        collisions = self.collision_rows
        if collisions.stale():  # the pairs rebuilt: obstacles added or removed, ports
            if collisions.pair_count() > self.pair_capacity:
                self._grow(collisions.pair_count())
                return self._solve_with_pairs(q, twist)
            collisions.describe()
        pairs = None
        if collisions.fallback is not None:
            q, twist = self._checked(q, twist)
            pairs = self._write_python_pairs(q)
        qd, paper_form = self._run(q, twist)
        if pairs is None:
            pairs = collisions.rows()
        return qd, self._report_with_pairs(self._step.report, paper_form, pairs)

    def _report_with_pairs(self, report: Report, paper_form: bool,
                           pairs: CollisionRows) -> StepReport:
        """:meth:`_step_report` with the step's collision rows and the pairs it held."""
        count = self._step.active_pair_count
        step_report = self._step_report(report, paper_form)
        step_report.collision = pairs
        step_report.active_pairs = tuple(self._active_pairs[:count].tolist())
        return step_report

    def _write_python_pairs(self, q: np.ndarray) -> CollisionRows:
        """The collision rows at ``q`` measured by Python on ``data`` and written into the
        C++ step's buffer (sized for every pair before the pairs are described)."""
        model, data = self.setup.model, self.data
        pin.computeJointJacobians(model, data, q)
        bounds = self.setup.bounds
        pairs = braked_pairs(self._collisions.rows(model, data), self._collisions,
                             bounds.acceleration_limit, bounds.dt)
        self._pair_rows[:pairs.size] = pairs.rows
        self._pair_lower[:pairs.size] = pairs.lower
        self._step.set_pair_count(pairs.size)
        return pairs

    @property
    def pair_capacity(self) -> int:
        """How many collision rows the C++ step's buffer takes."""
        return self._step.pair_capacity

    def _grow(self, pair_capacity: int) -> None:
        """Build the C++ step again with room for ``pair_capacity`` collision rows, from
        the command last sent."""
        previous, change = self.previous.copy(), self.previous_change.copy()
        CompiledStep.__init__(self, self.setup, self.data, pair_capacity, self._event_capacity)
        self.previous[:] = previous
        self.previous_change[:] = change

    def _checked(self, q: np.ndarray, twist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return checked_inputs(q, twist, self.setup.model.nq, self.setup.task_size)

    def _write_in_python(self) -> bool:
        """The terms of the constraints that declare no compiled form, and a posture
        velocity Python computes; returns whether the paper's form is defined (else the
        analytical form may not run)."""
        setup = self.setup
        paper_form = True
        gaps, gains = self._step.damper_gaps, self._step.damper_gains
        for index, writer, terms, rotation, translation in self._in_python:
            placement = pin.SE3(rotation, translation)
            if not writer.constraint.is_equality:
                gaps[index] = writer.constraint.error(placement)[0]
                gains[index] = writer.constraint.gain
            if self._paper and not paper_form_defined(writer.constraint, placement):
                paper_form, writer = False, self._fallback_writer
            writer.write(placement, terms)
        if self._posture_in_python:
            self.pipeline.posture[:] = setup.posture_velocity(self.pipeline.q)
        return paper_form

    def _step_report(self, report: Report, paper_form: bool) -> StepReport:
        """The C++ report as a :class:`StepReport` with its lists and events (the paper's
        form undefined: its event first, as the Python step records it;
        ``dropped_events``: the events past the C++ record)."""
        recorded = [] if paper_form else [(Event.PAPER_FORM_UNDEFINED, 0.0, 0.0, 0.0)]
        if report.event_count:
            recorded += [(EVENT_BY_CODE[int(code)], a, b, c)
                         for code, a, b, c in self._events[:report.event_count].tolist()]
        saturated, barriers = report.saturated_count, report.active_barrier_count
        saturation_joints = report.saturation_joint_count
        step_report = StepReport(
            STATUSES[report.status], METHODS[report.method], report.sigma_min, report.damping,
            report.scale, report.equality_residual,
            tuple(self._saturated[:saturated].tolist()) if saturated else (),
            tuple(self._active_barriers[:barriers].tolist()) if barriers else (),
            tuple(recorded),
            tuple(self._saturation_joints[:saturation_joints].tolist()) if saturation_joints else ())
        if report.dropped_event_count:  # rare: no keyword argument on the common path
            step_report.dropped_events = report.dropped_event_count
        return step_report

    def time_steps(self, configurations: np.ndarray, twists: np.ndarray) -> np.ndarray | None:
        """The C++ floor (docs/design.md section 16): per-step nanoseconds of this step in
        a C++ loop over ``configurations`` (steps x nq) and ``twists`` (steps x stacked
        twist), no Python between the steps (the collision rows measured in the C++ step
        too); ``None`` when a step is not one C++ call (Python writes terms, a posture
        velocity or collision rows between two calls)."""
        if not self._one_call:
            return None
        self.run_report()
        if self._collisions is not None:
            if self.collision_rows.stale():  # describe the pairs (the first step does)
                self.solve(configurations[0], twists[0])
            if self.collision_rows.fallback is not None:
                return None
        return self.pipeline.time_steps(np.asarray(configurations, dtype=float),
                                        np.asarray(twists, dtype=float), self._use_posture)

    # -- what the loop's compiled tick needs (compiled_tick.py, docs/design.md 5.1) ------

    @property
    def tick_ready(self) -> bool:
        """Whether the loop's compiled tick can run this step around its pipeline: with
        collision rows, only while the pipeline measures them (described since the pairs
        last changed, no shape left to Python)."""
        rows = self.collision_rows
        return rows is None or (not rows.stale() and rows.fallback is None)

    @property
    def one_call(self) -> bool:
        """Whether the pipeline computes every term itself (else :meth:`write_terms`)."""
        return self._one_call

    @property
    def use_posture(self) -> bool:
        return self._use_posture

    @property
    def paper_form(self) -> bool:
        """Whether the paper's form was defined at the pipeline's last step (always, when
        the step does not use it)."""
        return not self._paper or self.pipeline.paper_form

    def write_terms(self) -> bool:
        """The terms Python writes between the pipeline's kinematics and its step; whether
        the paper's form is defined (:meth:`last_report` takes it)."""
        return self._write_in_python() and self.pipeline.paper_form

    def last_report(self, paper_form: bool) -> StepReport:
        """The report of the step the pipeline has just run, as :meth:`solve` gives it."""
        report = self._step.report
        if self._collisions is not None:
            return self._report_with_pairs(report, paper_form, self.collision_rows.rows())
        # no list, no event (so none dropped: the record holds at least one)
        if paper_form and not (report.saturated_count or report.active_barrier_count
                               or report.event_count):
            return StepReport(STATUSES[report.status], METHODS[report.method], report.sigma_min,
                              report.damping, report.scale, report.equality_residual)
        return self._step_report(report, paper_form)
