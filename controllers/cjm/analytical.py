"""The analytical CJM: one equality constraint with at least 6 joints before it.

Paper eqs 17-24 and 29-32, docs/design.md section 4::

    V_a  = S [u; w] + V_a0                       (S from the constraint, V_a0 = [C^T b; 0])
    V_e  = Ad_ea V_a + J_post qd_post
    Jbar = [Ad_ea S, J_post]                     (the CJM, 6 x (6 - k + n_post))
    [u; w; qd_post] = Jbar^-1 (V_e - Ad_ea V_a0) (eq 22; damped, eq 35, near singular)
    qd_pre = J_a^-1 V_a                          (J_a^+ V_a + posture in null(J_a) if > 6)

The constraint holds by construction for any solution of the small system.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import eigenpy
import numpy as np
import pinocchio as pin

from constraints import Constraint, ConstraintPoint, Parametrisation, structure_of

from ..base import TWIST_TOLERANCE, StepStatus
from ..linalg import DampedSolution, DampingPolicy, damped_least_squares, nullspace_basis
from .affine_forms import AffineForm, affine_form_of, affine_inputs
from .report import Event, StepReport
from .tolerances import (
    FAST_PATH_MIN_SIGMA,
    LEAST_SQUARES_RCOND,
    PRE_CHAIN_MIN_SINGULAR_VALUE,
    PRE_CHAIN_PIVOT_RATIO,
)

@dataclass(frozen=True)
class ChainSplit:
    """Velocity indices of the joints before (moving ``F_a``) and after the constraint on
    the path to the EE, and of the others (``off``: they move neither, e.g. fingers)."""

    pre: np.ndarray
    post: np.ndarray
    off: np.ndarray


def chain_split(model: pin.Model, frame_id: int, ee_frame_id: int) -> ChainSplit | None:
    """Joints before/after the link of ``frame_id`` on the path to the EE; None when the
    EE is not downstream of that link (the analytical form does not apply)."""
    pre_joints = [j for j in model.supports[model.frames[frame_id].parentJoint] if j != 0]
    ee_path = [j for j in model.supports[model.frames[ee_frame_id].parentJoint] if j != 0]
    if not set(pre_joints) <= set(ee_path):
        return None
    post_joints = [j for j in ee_path if j not in pre_joints]

    def velocity_indices(joints: list[int]) -> np.ndarray:
        return np.array([i for j in joints for i in range(model.idx_vs[j], model.idx_vs[j] + model.nvs[j])],
                        dtype=int)

    off_joints = [j for j in range(1, model.njoints) if j not in ee_path]
    return ChainSplit(pre=velocity_indices(pre_joints), post=velocity_indices(post_joints),
                      off=velocity_indices(off_joints))


# -- the per-step terms, as one flat buffer ------------------------------------------------


def terms_size(k: int) -> int:
    """Entries of the flat terms buffer for a constraint of ``k`` rows."""
    return 6 * (7 - k) + 7 * k


def terms_views(terms: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Views ``(pre_rhs, residual_rows)`` into a flat terms buffer.

    ``pre_rhs = [V_a0, S]`` (6 x (7 - k), column-major, as LAPACK and Eigen store it) is
    what the pre-chain's ``J_a`` is solved against; ``residual_rows = [-b, C [I, -hat(p)]]``
    (k x 7) gives the residual ``C v_c - b = residual_rows [1; V_a]`` of a twist of ``F_a``.
    """
    split = 6 * (7 - k)
    return terms[:split].reshape(7 - k, 6).T, terms[split:].reshape(k, 7)


def write_terms(state: ConstraintPoint, structure: np.ndarray, terms: np.ndarray) -> None:
    """Fill a flat terms buffer from an evaluated constraint and its structure matrix."""
    pre_rhs, residual_rows = terms_views(terms, state.C.shape[0])
    pre_rhs[:3, 0] = state.C.T @ state.rhs
    pre_rhs[3:, 0] = 0.0
    pre_rhs[:, 1:] = structure
    residual_rows[:, 0] = -state.rhs
    residual_rows[:, 1:4] = state.C
    residual_rows[:, 4:] = -state.C @ pin.skew(state.p)


class AffineTerms:
    """The terms of a constraint with an affine form, as
    ``t_0 + T_x x + T_f f + K (t_K + T_K x)`` at its gain ``K``.

    When the constraint's type has an affine form (:mod:`.affine_forms`: ``(x, f)`` its
    anchor in ``F_a`` coordinates, the evaluation affine in them with constant ``C``; a
    hole: ``x`` its centre, ``f`` its velocity),
    the null-space structure matrix ``[[C_perp^T, C^T C hat(p)], [0, I]]`` is affine
    too (``hat`` is linear), so the whole buffer is; ``rhs = C v - K e`` (with ``e``
    affine in ``x``) is affine in the gain as well. The maps are found by evaluating at
    ``x, f = 0`` and at the unit vectors, the right-hand side taken at gain 0 and 1; a
    step is then a few matrix products with the gain it reads (docs/design.md section 16).
    """

    def __init__(self, constraint: Constraint, form: AffineForm) -> None:
        self.constraint = constraint
        self.form = form
        k = constraint.dim
        zero = np.zeros(3)

        def terms_at(x: np.ndarray, f: np.ndarray, gain: float) -> np.ndarray:
            state = form.evaluate(constraint, x, f)
            # rhs = C v - K e at the constraint's gain K: the same point at ``gain``
            state = dataclasses.replace(state, rhs=state.rhs + (constraint.gain - gain) * state.error)
            terms = np.empty(terms_size(k))
            write_terms(state, structure_of(state, "nullspace"), terms)
            return terms

        self.offset = terms_at(zero, zero, 0.0)
        self.of_x = np.column_stack([terms_at(e, zero, 0.0) - self.offset for e in np.eye(3)])
        self.of_f = np.column_stack([terms_at(zero, e, 0.0) - self.offset for e in np.eye(3)])
        self.offset_per_gain = terms_at(zero, zero, 1.0) - self.offset
        self.of_x_per_gain = np.column_stack(
            [terms_at(e, zero, 1.0) - self.offset_per_gain - self.offset for e in np.eye(3)]) - self.of_x
        #: ``[t_0, T_x, T_K, t_K]``: the terms are this times ``[1; x; K x; K]``
        self._stacked = np.column_stack([self.offset, self.of_x, self.of_x_per_gain,
                                         self.offset_per_gain])

    def write(self, x: np.ndarray, f: np.ndarray | None, terms: np.ndarray) -> None:
        """The terms at ``(x, f)`` and the constraint's gain now."""
        gain = self.constraint.gain
        x0, x1, x2 = x.tolist()
        np.dot(self._stacked, [1.0, x0, x1, x2, gain * x0, gain * x1, gain * x2, gain], out=terms)
        if f is not None:
            terms += self.of_f @ f


class TermsWriter:
    """Writes one constraint's flat terms buffer at its link's placement: through its
    affine form (:class:`AffineTerms`) where it has one and the parametrisation is the
    null-space one, else by evaluating the constraint. The Python step's, and the
    compiled step's for a constraint that declares no compiled form (section 16)."""

    def __init__(self, constraint: Constraint, parametrisation: Parametrisation) -> None:
        self.constraint = constraint
        self.parametrisation = parametrisation
        #: the affine form, or None: the terms come from evaluating the constraint
        form = affine_form_of(constraint) if parametrisation == "nullspace" else None
        self.affine_terms = None if form is None else AffineTerms(constraint, form)

    def write(self, placement: pin.SE3, terms: np.ndarray) -> None:
        if self.affine_terms is None:
            state = self.constraint.evaluate(placement)
            write_terms(state, structure_of(state, self.parametrisation), terms)
            return
        affine = self.affine_terms
        affine.write(*affine_inputs(affine.form, self.constraint, placement), terms)


class SquarePreChain:
    """The paper's case: one constraint, exactly 6 joints before it, buffers allocated once.

    With ``pre_solution = J_a^-1 [V_a0, S]`` (one LU solve) the joint velocities are
    affine in the free variables ``v_m = [u; w; qd_post]``::

        qd = joint_map [1; v_m],   joint_map = [[pre_solution, 0], [0, I]]  (pre, post rows)

    and ``J_e joint_map = [J_e qd_0, Jbar]``: since ``J_e[:, pre] = Ad_ea J_a``, the
    columns of ``J_e[:, pre] J_a^-1 S`` are ``Ad_ea S``, the CJM of eq 24, built without
    an adjoint or an ``SE3`` object.
    """

    def __init__(self, constraint: Constraint, frame_id: int, nv: int, split: ChainSplit,
                 parametrisation: Parametrisation) -> None:
        self.frame_id = frame_id
        self.terms_writer = TermsWriter(constraint, parametrisation)
        k = constraint.dim
        self.n_free = 6 - k
        n_columns = self.n_free + split.post.size  # columns of Jbar
        pre = split.pre
        contiguous = np.array_equal(pre, np.arange(pre[0], pre[0] + pre.size))
        self.pre = slice(int(pre[0]), int(pre[0]) + pre.size) if contiguous else pre
        self.terms = np.empty(terms_size(k))
        self.pre_rhs, self.residual_rows = terms_views(self.terms, k)
        self.joint_map = np.zeros((nv, n_columns + 1))
        self.joint_map[split.post, self.n_free + 1:] = np.eye(split.post.size)
        self.task_map = np.empty((6, n_columns + 1))  # [J_e qd_0, Jbar]
        self.square = n_columns == 6
        self.cjm_rhs = np.empty(6)
        self.free_with_one = np.ones(n_columns + 1)  # [1; v_m]
        self.twist_a_with_one = np.ones(7)  # [1; V_a]
        # Eigen's partial-pivoting LU through eigenpy (Pinocchio's own bindings): the
        # factorisation of LAPACK's dgesv, reused objects, less call overhead.
        self.lu_pre = eigenpy.PartialPivLU(6)
        self.lu_cjm = eigenpy.PartialPivLU(6)

    def solve(self, model: pin.Model, data: pin.Data, ee_jacobian: np.ndarray,
              twist: np.ndarray, policy: DampingPolicy, report: StepReport,
              posture_velocity: np.ndarray | None = None) -> np.ndarray | None:
        """``qd`` for ``twist``, or None when ``J_a`` is near singular (general form then).

        A wide ``Jbar`` (more free variables than 6) leaves a null space; it is spent as
        the general form spends it: the ``qd`` closest to ``posture_velocity`` (zero: the
        minimum-norm ``qd``) among those that meet the rows and the task.

        Written flat, with the buffers of the plan: from Python every NumPy or LAPACK call
        costs about the same whatever the size, so the step is counted in calls.
        """
        self.terms_writer.write(pin.updateFramePlacement(model, data, self.frame_id), self.terms)
        jacobian_a = pin.getFrameJacobian(model, data, self.frame_id, pin.LOCAL)
        lu_pre = self.lu_pre
        lu_pre.compute(jacobian_a[:, self.pre])
        pivots = list(map(abs, lu_pre.matrixLU().diagonal().tolist()))
        if not min(pivots) >= PRE_CHAIN_PIVOT_RATIO * max(pivots):  # NaN included
            report.event(Event.PRE_CHAIN_SINGULAR)
            return None
        joint_map = self.joint_map
        joint_map[self.pre, :self.n_free + 1] = lu_pre.solve(self.pre_rhs)
        task_map = np.dot(ee_jacobian, joint_map, out=self.task_map)
        np.subtract(twist, task_map[:, 0], out=self.cjm_rhs)  # V_e - Ad_ea V_a0 (eq 22)
        if not self._solve_by_lu(task_map[:, 1:], policy, report):  # the SVD DLS (eq 35)
            solution = damped_least_squares(task_map[:, 1:], self.cjm_rhs, policy)
            self.free_with_one[1:] = solution.x
            report_task_solution(solution, task_map[:, 1:], self.cjm_rhs, report)
            if solution.rank < solution.x.size:
                self._closest_to_posture(task_map[:, 1:], posture_velocity)
        qd = np.dot(joint_map, self.free_with_one)  # a new array: the caller keeps it
        # residual of C v_c = b for the twist the pre-chain really produces
        np.dot(jacobian_a, qd, out=self.twist_a_with_one[1:])
        report.equality_residual = max(map(abs, np.dot(self.residual_rows, self.twist_a_with_one).tolist()))
        report.method = "analytical"
        return qd

    def _closest_to_posture(self, cjm: np.ndarray, posture_velocity: np.ndarray | None) -> None:
        """Move the free variables within ``null(Jbar)`` to the ``qd`` closest to the posture."""
        null_basis = nullspace_basis(cjm)
        qd = self.joint_map @ self.free_with_one
        goal = -qd if posture_velocity is None else posture_velocity - qd
        step, *_ = np.linalg.lstsq(self.joint_map[:, 1:] @ null_basis, goal, rcond=LEAST_SQUARES_RCOND)
        self.free_with_one[1:] += null_basis @ step

    def _solve_by_lu(self, cjm: np.ndarray, policy: DampingPolicy, report: StepReport) -> bool:
        """Solve a square, well-conditioned ``Jbar`` by its LU, where damping cannot act.

        ``||Jbar^-1||_2 <= ||Jbar^-1||_F``, so ``1 / ||Jbar^-1||_F`` is a lower bound on
        ``sigma_min``: at or above the damping threshold the DLS (eq 35) is the exact
        inverse (eq 22). An exactly singular ``Jbar`` gives inf or NaN here, and False.
        """
        if not (self.square and policy.damping == 0.0):
            return False
        lu_cjm = self.lu_cjm
        lu_cjm.compute(cjm)
        inverse = lu_cjm.inverse().ravel()
        bound = 1.0 / math.sqrt(float(np.dot(inverse, inverse)))
        if not (bound >= policy.threshold and bound >= FAST_PATH_MIN_SIGMA):
            return False
        self.free_with_one[1:] = lu_cjm.solve(self.cjm_rhs)
        report.sigma_min = bound
        return True


def report_task_solution(solution: DampedSolution, matrix: np.ndarray, rhs: np.ndarray,
                         report: StepReport) -> None:
    """Record a DLS solution of the task in ``report``; a task not met is ``least_squares``."""
    report.sigma_min = solution.sigma_min
    report.damping = solution.damping
    if solution.exact:
        return
    residual = float(np.max(np.abs(matrix @ solution.x - rhs), initial=0.0))
    if residual > TWIST_TOLERANCE * (1.0 + float(np.max(np.abs(rhs), initial=0.0))):
        report.event(Event.TASK_RESIDUAL, StepStatus.LEAST_SQUARES, solution.damping, residual)


def solve_redundant_pre_chain(model: pin.Model, data: pin.Data, ee_jacobian: np.ndarray,
                              ee_placement: pin.SE3, constraint: Constraint, frame_id: int,
                              split: ChainSplit, twist: np.ndarray, policy: DampingPolicy,
                              parametrisation: Parametrisation, posture_velocity: np.ndarray | None,
                              report: StepReport) -> np.ndarray | None:
    """More than 6 joints move ``F_a``: SVD of ``J_a``, posture in its null space."""
    placement = data.oMf[frame_id]
    pre_jacobian = pin.getFrameJacobian(model, data, frame_id, pin.LOCAL)[:, split.pre]
    state = constraint.evaluate(placement)
    structure = structure_of(state, parametrisation)
    n_free = structure.shape[1]
    ad_ea = ee_placement.actInv(placement).action
    # Jbar = [Ad_ea S, J_post] (eq 24); the particular twist V_a0 = [C^T b; 0] carries the
    # drift feedback and feed-forward, so the free variables solve Jbar v_m = V_e - Ad_ea V_a0
    cjm = np.empty((6, n_free + split.post.size))
    cjm[:, :n_free] = ad_ea @ structure
    cjm[:, n_free:] = ee_jacobian[:, split.post]
    particular_linear = state.C.T @ state.rhs
    cjm_rhs = twist - ad_ea[:, :3] @ particular_linear
    solution = damped_least_squares(cjm, cjm_rhs, policy)
    twist_a = structure @ solution.x[:n_free]
    twist_a[:3] += particular_linear

    u, s, vt = np.linalg.svd(pre_jacobian, full_matrices=True)
    if s[-1] < PRE_CHAIN_MIN_SINGULAR_VALUE:
        report.event(Event.PRE_CHAIN_SINGULAR)
        return None
    qd_pre = vt[:6].T @ ((u.T @ twist_a) / s)
    if posture_velocity is not None:
        null_basis = vt[6:]
        qd_pre += null_basis.T @ (null_basis @ posture_velocity[split.pre])

    qd = np.zeros(model.nv)
    qd[split.pre] = qd_pre
    qd[split.post] = solution.x[n_free:]
    achieved = pre_jacobian @ qd_pre  # the twist the pre-chain really produces
    point_velocity = achieved[:3] - pin.skew(state.p) @ achieved[3:]
    report.equality_residual = float(np.max(np.abs(state.C @ point_velocity - state.rhs)))
    report.method = "analytical"
    report_task_solution(solution, cjm, cjm_rhs, report)
    return qd
