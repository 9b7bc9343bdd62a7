"""The Constrained Jacobian Matrix controller (the paper's method, sections 4-7)."""

from __future__ import annotations

import dataclasses

import math
import operator
from dataclasses import dataclass
from typing import Iterable

import eigenpy
import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.base import Parametrisation, analytical_terms_views, as_vector, structure_of

from .base import Controller, Kinematics
from .linalg import DampingPolicy, damped_least_squares, nullspace

#: Below this smallest singular value of J_a (the Jacobian of F_a over the joints before
#: the constraint; for the square case, the smallest/largest LU pivot ratio) F_a can no
#: longer take every twist at a sane joint speed (``J_a^-1`` would amplify by more than
#: ~1/PRE_CHAIN_SINGULAR), and the analytical form hands over to the general null-space
#: form, which holds the rows exactly and damps the near-singular direction instead.
PRE_CHAIN_SINGULAR = 1e-2

#: The LU fast path for a square ``Jbar`` needs the certified lower bound on its smallest
#: singular value to be at least this as well as the damping threshold, so the SVD path
#: keeps every nearly rank-deficient case (it drops singular values below 1e-10).
FAST_PATH_MIN_SIGMA = 1e-6


@dataclass(frozen=True)
class ChainSplit:
    """Velocity indices of the joints before (moving ``F_a``) and after the constraint."""

    pre: np.ndarray
    post: np.ndarray


class _SquarePlan:
    """Buffers of the analytical CJM for one constraint on a 6-joint pre-chain.

    With ``X = J_a^-1 [V_a0, S]`` (one LU solve) the joint velocities are affine in the
    free variables ``v_m = [u; w; qd_post]``::

        qd = W [1; v_m],   W = [[X, 0], [0, I]]   (rows: pre, post joints)

    and ``J_e W = [J_e qd_0, Jbar]``: since ``J_e[:, pre] = Ad_ea J_a``, the columns of
    ``J_e[:, pre] J_a^-1 S`` are ``Ad_ea S``, the CJM of eq 24, built without an adjoint
    or an ``SE3`` object. Everything here is allocated once; each step writes into it.
    """

    def __init__(self, constraint: Constraint, frame_id: int, nv: int, split: ChainSplit) -> None:
        self.constraint = constraint
        self.frame_id = frame_id
        k = constraint.dim
        self.n_free = 6 - k
        m = self.n_free + split.post.size  # columns of Jbar
        pre = split.pre
        contiguous = np.array_equal(pre, np.arange(pre[0], pre[0] + pre.size))
        self.pre = slice(int(pre[0]), int(pre[0]) + pre.size) if contiguous else pre
        self.terms = np.empty(6 * (7 - k) + 7 * k)
        self.B, self.R = analytical_terms_views(self.terms, k)  # [V_a0, S], [-b, C[I, -hat p]]
        self.W = np.zeros((nv, m + 1))
        self.W[split.post, self.n_free + 1:] = np.eye(split.post.size)
        self.JW = np.empty((6, m + 1))
        self.square = m == 6
        self.rhs = np.empty(6)
        self.v1 = np.ones(m + 1)  # [1; v_m]
        self.twist1 = np.ones(7)  # [1; V_a]
        # Eigen's partial-pivoting LU through eigenpy (Pinocchio's own bindings): the same
        # factorisation as LAPACK's dgesv, reused objects, a little less call overhead.
        self.lu_a = eigenpy.PartialPivLU(6)
        self.lu_bar = eigenpy.PartialPivLU(6)


class CJMController(Controller):
    """Joint velocities from an EE twist through the Constrained Jacobian Matrix.

    **Analytical form** (one equality constraint, at least 6 joints before it; paper eqs
    17-24 and 29-32, DESIGN.md section 4)::

        V_a  = S [u; w] + V_a0                       (S from the constraint, V_a0 = drift)
        V_e  = Ad_ea V_a + J_post qd_post
        Jbar = [Ad_ea S, J_post]                     (the CJM, 6 x (6 - k + n_post))
        [u; w; qd_post] = Jbar^-1 (V_e - Ad_ea V_a0) (eq 22; damped, eq 35, near singular)
        qd_pre = J_a^-1 V_a                          (J_a^+ V_a + posture in null(J_a) if > 6)

    The constraint holds by construction for any solution of the small system.

    **General form** (several constraints, barriers switched on, fewer than 6 joints
    before the constraint, or a singular pre-chain)::

        A qd = b  ->  qd = qd_0 + N y,  N = null(A),  qd_0 = A^+ b
        y = (J_e N)^+ (V_e - J_e qd_0)    (damped), posture in null(J_e N)

    **Speed.** For the paper's case (6 joints before the constraint) one step costs two
    6 x 6 LU factorisations and a handful of NumPy calls into buffers allocated once (see
    ``_SquarePlan``). A square ``Jbar`` is solved by its LU whenever the damping cannot
    act: constant damping 0 and the certified bound ``sigma_min >= 1 / ||Jbar^-1||_F``
    at or above both ``singular_threshold`` and ``FAST_PATH_MIN_SIGMA``. There the damped
    least squares (eq 35) is the exact inverse (eq 22), so this fast path changes no
    result beyond rounding; ``info.sigma_min`` then reports the bound, which lies within
    a factor ``sqrt(6)`` below the true value. Anywhere else (near a singularity,
    constant damping, a wide ``Jbar``) one SVD computes the DLS as before. (The DLS also
    drops singular values below ``1e-10 max(1, sigma_max)``; the fast path's
    ``sigma_min >= 1e-6`` keeps clear of that for any ``sigma_max`` below 1e4, i.e. any
    arm shorter than kilometres.)

    **Barriers** are held as plane equalities once the unconstrained solution would
    break them (an active set, one barrier at a time, most violated first).

    Parameters
    ----------
    robot, constraints, strict : see :class:`controllers.base.Controller`.
    damping : constant DLS damping ``lambda`` (paper eq 35); 0 gives the exact inverse.
    singular_threshold, max_damping : the rising damping near singularity
        (:class:`controllers.linalg.DampingPolicy`).
    parametrisation : ``"nullspace"`` (singularity-free, default) or ``"paper"`` (the
        ``1/a`` form of eqs 9-13).
    posture : configuration the redundancy is spent on (default ``robot.q_home``).
    posture_gain : gain (1/s) of the null-space posture task; 0 gives minimum norm.
    general_only : always use the general null-space form (the cross-check).
    respect_velocity_limits : when a joint would exceed its velocity limit, scale the
        twist's part of ``qd`` (not the constraint's) so none does: the constraint holds.
    """

    def __init__(
        self,
        robot,
        constraints: Iterable[Constraint] = (),
        damping: float = 0.0,
        singular_threshold: float = 0.01,
        max_damping: float = 0.05,
        parametrisation: Parametrisation = "nullspace",
        posture: np.ndarray | None = None,
        posture_gain: float = 1.0,
        general_only: bool = False,
        respect_velocity_limits: bool = True,
        strict: bool = False,
    ) -> None:
        if parametrisation not in ("nullspace", "paper"):
            raise ValueError(f"unknown parametrisation {parametrisation!r}: 'nullspace' or 'paper'")
        self.policy = DampingPolicy(float(damping), float(singular_threshold), float(max_damping))
        self.parametrisation = parametrisation
        self.posture_gain = float(posture_gain)
        if not np.isfinite(self.posture_gain) or self.posture_gain < 0:
            raise ValueError(f"posture_gain must be finite and >= 0, got {posture_gain}")
        self.general_only = bool(general_only)
        self.respect_velocity_limits = bool(respect_velocity_limits)
        self._splits: dict[int, ChainSplit | None] = {}
        self._plans: dict[int, _SquarePlan] = {}
        self._equalities: list[int] = []
        self._barriers: list[int] = []
        super().__init__(robot, constraints, strict=strict)
        if posture is None:
            posture = getattr(robot, "q_home", None)
        self.posture = (pin.neutral(self.model) if posture is None
                        else as_vector(posture, self.model.nq, "posture"))
        limit = self.velocity_limit
        #: 1 / velocity limit per joint (0 where unlimited), as a list for a Python loop
        self._inverse_limit = [0.0 if not np.isfinite(v) else 1.0 / v for v in limit.tolist()]

    # -- chain structure ---------------------------------------------------------------

    def split(self, frame_id: int) -> ChainSplit | None:
        """Joints before/after the link of ``frame_id`` on the path to the EE.

        ``None`` when the EE is not downstream of that link (the analytical form does not
        apply).
        """
        if frame_id not in self._splits:
            self._splits[frame_id] = self._compute_split(frame_id)
        return self._splits[frame_id]

    def _compute_split(self, frame_id: int) -> ChainSplit | None:
        model = self.model
        joint_a = model.frames[frame_id].parentJoint
        ee_joint = model.frames[self.ee_frame_id].parentJoint
        pre_joints = [j for j in model.supports[joint_a] if j != 0]
        ee_path = [j for j in model.supports[ee_joint] if j != 0]
        if not set(pre_joints) <= set(ee_path):
            return None
        post_joints = [j for j in ee_path if j not in pre_joints]

        def velocity_indices(joints: list[int]) -> np.ndarray:
            return np.array(
                [i for j in joints for i in range(model.idx_vs[j], model.idx_vs[j] + model.nvs[j])],
                dtype=int,
            )

        return ChainSplit(pre=velocity_indices(pre_joints), post=velocity_indices(post_joints))

    def constrained_jacobian(self, q: np.ndarray, index: int = 0) -> np.ndarray:
        """The CJM ``Jbar = [Ad_ea S, J_post]`` of constraint ``index`` at ``q`` (eq 24)."""
        q = as_vector(q, self.model.nq, "q")
        self._kinematics(q)
        frame_id = self.constraint_frames[index]
        split = self.split(frame_id)
        if split is None:
            raise ValueError(f"the EE is not downstream of link {self.constraints[index].link!r}")
        placement = self.data.oMf[frame_id]
        S = self.constraints[index].structure(placement, self.parametrisation)
        ad_ea = (self.data.oMf[self.ee_frame_id].actInv(placement)).action
        ee_jacobian = pin.getFrameJacobian(self.model, self.data, self.ee_frame_id, pin.LOCAL)
        return np.hstack([ad_ea @ S, ee_jacobian[:, split.post]])

    # -- the step ----------------------------------------------------------------------

    def _on_constraints_changed(self) -> None:
        self._equalities = [i for i, c in enumerate(self.constraints) if c.is_equality]
        self._barriers = [i for i, c in enumerate(self.constraints) if not c.is_equality]
        self._plans = {}

    def _solve(self, kinematics: Kinematics, twist: np.ndarray) -> np.ndarray:
        if not self._barriers:
            qd = self._solve_active(kinematics, twist, self._equalities)
            return self._limit_velocity(qd, kinematics, self._equalities)
        active = list(self._equalities)
        qd = self._solve_active(kinematics, twist, active)
        # Active set over the barriers: hold the most violated one, solve again.
        barriers = list(self._barriers)
        while barriers:
            violations = []
            for i in barriers:
                A, b = self.constraints[i].rows(self.model, self.data, self.constraint_frames[i])
                violations.append(float(b[0] - A[0] @ qd))
            worst = int(np.argmax(violations))
            if violations[worst] <= 1e-12:
                break
            active.append(barriers.pop(worst))
            qd = self._solve_active(kinematics, twist, active)
        if self._barriers:
            self.info.active_barriers = tuple(i for i in active if i in self._barriers)
        return self._limit_velocity(qd, kinematics, active)

    def _solve_active(self, kinematics: Kinematics, twist: np.ndarray, active: list[int]) -> np.ndarray:
        if len(active) == 1 and not self.general_only:
            plan = self._plans.get(active[0])  # the paper's case, seen before
            if plan is not None:
                qd = self._solve_square_pre_chain(kinematics, twist, plan)
                if qd is not None:
                    return qd
                return self._solve_general(kinematics, twist, active)
            split = self.split(self.constraint_frames[active[0]])
            if split is not None and split.pre.size >= 6:
                qd = self._solve_analytical(kinematics, twist, active[0], split)
                if qd is not None:
                    return qd
        return self._solve_general(kinematics, twist, active)

    def _posture_velocity(self, q: np.ndarray) -> np.ndarray:
        return self.posture_gain * pin.difference(self.model, q, self.posture)

    def _solve_analytical(
        self, kinematics: Kinematics, twist: np.ndarray, index: int, split: ChainSplit
    ) -> np.ndarray | None:
        if split.pre.size == 6:
            plan = self._plans.get(index)
            if plan is None:
                plan = self._plans[index] = _SquarePlan(
                    self.constraints[index], self.constraint_frames[index], self.model.nv, split)
            return self._solve_square_pre_chain(kinematics, twist, plan)
        return self._solve_redundant_pre_chain(kinematics, twist, index, split)

    def _solve_square_pre_chain(
        self, kinematics: Kinematics, twist: np.ndarray, plan: _SquarePlan
    ) -> np.ndarray | None:
        """The paper's case, ``J_a`` square: see :class:`_SquarePlan` for the algebra.

        Written flat, with the buffers of the plan: from Python every NumPy or LAPACK
        call costs about a microsecond whatever the size, so the step is counted in calls.
        """
        model, data, info = self.model, self.data, self.info
        plan.constraint.analytical_terms(pin.updateFramePlacement(model, data, plan.frame_id),
                                         self.parametrisation, plan.terms)
        jacobian_a = pin.getFrameJacobian(model, data, plan.frame_id, pin.LOCAL)
        # X = J_a^-1 [V_a0, S]; an LU pivot far below the largest flags a singular J_a
        lu_a = plan.lu_a
        lu_a.compute(jacobian_a[:, plan.pre])
        pivots = list(map(abs, lu_a.matrixLU().diagonal().tolist()))
        if not min(pivots) >= PRE_CHAIN_SINGULAR * max(pivots):  # NaN included
            info.message = "pre-constraint chain singular: general form used"
            return None
        W = plan.W
        W[plan.pre, :plan.n_free + 1] = lu_a.solve(plan.B)
        JW = np.dot(kinematics.ee_jacobian, W, out=plan.JW)  # [J_e qd_0, Jbar]
        np.subtract(twist, JW[:, 0], out=plan.rhs)  # V_e - Ad_ea V_a0 (eq 22)
        policy = self.policy
        solved = False
        if plan.square and policy.damping == 0.0:
            lu_bar = plan.lu_bar
            lu_bar.compute(JW[:, 1:])
            inverse = lu_bar.inverse().ravel()
            # ||Jbar^-1||_2 <= ||Jbar^-1||_F, so this bound never exceeds sigma_min (an
            # exactly singular Jbar gives inf or NaN here, and the SVD path)
            bound = 1.0 / math.sqrt(float(np.dot(inverse, inverse)))
            if bound >= policy.threshold and bound >= FAST_PATH_MIN_SIGMA:
                plan.v1[1:] = lu_bar.solve(plan.rhs)
                info.sigma_min = bound
                solved = True
        if not solved:  # near singular, damped or not square: the SVD DLS (eq 35)
            solution = damped_least_squares(JW[:, 1:], plan.rhs, policy)
            plan.v1[1:] = solution.x
            info.sigma_min = solution.sigma_min
            info.damping = solution.damping
        qd = np.dot(W, plan.v1)  # a new array: the caller keeps it
        # residual of C v_c = b for the twist the pre-chain really produces
        np.dot(jacobian_a, qd, out=plan.twist1[1:])
        residual = np.dot(plan.R, plan.twist1).tolist()
        info.equality_residual = max(map(abs, residual))
        info.method = "analytical"
        return qd

    def _solve_redundant_pre_chain(
        self, kinematics: Kinematics, twist: np.ndarray, index: int, split: ChainSplit
    ) -> np.ndarray | None:
        """More than 6 joints move ``F_a``: SVD of ``J_a``, posture in its null space."""
        frame_id = self.constraint_frames[index]
        placement = self.data.oMf[frame_id]
        pre_jacobian = pin.getFrameJacobian(self.model, self.data, frame_id, pin.LOCAL)[:, split.pre]
        state = self.constraints[index].evaluate(placement)
        S = structure_of(state, self.parametrisation)
        n_free = S.shape[1]
        ad_ea = kinematics.ee_placement.actInv(placement).action
        # Jbar = [Ad_ea S, J_post] (eq 24); the particular twist V_a0 = [C^T b; 0] carries
        # the drift feedback and feed-forward, so the free variables solve
        # Jbar v_m = V_e - Ad_ea V_a0 (eq 22, damped as eq 35 near singularity).
        jbar = np.empty((6, n_free + split.post.size))
        jbar[:, :n_free] = ad_ea @ S
        jbar[:, n_free:] = kinematics.ee_jacobian[:, split.post]
        linear_a0 = state.C.T @ state.rhs
        solution = damped_least_squares(jbar, twist - ad_ea[:, :3] @ linear_a0, self.policy)
        twist_a = S @ solution.x[:n_free]
        twist_a[:3] += linear_a0

        u, s, vt = np.linalg.svd(pre_jacobian, full_matrices=True)
        if s[-1] < PRE_CHAIN_SINGULAR:
            self.info.message = "pre-constraint chain singular: general form used"
            return None
        qd_pre = vt[:6].T @ ((u.T @ twist_a) / s)
        if self.posture_gain > 0.0:
            null_basis = vt[6:]
            qd_pre += null_basis.T @ (null_basis @ self._posture_velocity(kinematics.q)[split.pre])

        qd = np.zeros(self.model.nv)
        qd[split.pre] = qd_pre
        qd[split.post] = solution.x[n_free:]
        # residual of C v_c = b for the twist the pre-chain really produces
        achieved = pre_jacobian @ qd_pre
        point_velocity = achieved[:3] - pin.skew(state.p) @ achieved[3:]
        self.info.equality_residual = float(np.max(np.abs(state.C @ point_velocity - state.rhs)))
        self.info.method = "analytical"
        self.info.sigma_min = solution.sigma_min
        self.info.damping = solution.damping
        return qd

    def _solve_general(self, kinematics: Kinematics, twist: np.ndarray, active: list[int]) -> np.ndarray:
        A, b = self.constraint_rows(active)
        null_basis, a_pinv, rank = nullspace(A)
        if rank < A.shape[0]:
            residual = float(np.max(np.abs(A @ (a_pinv @ b) - b)))
            if residual > 1e-9:
                self.info.message = (f"constraints conflict (rank {rank} < {A.shape[0]} rows, "
                                     f"least-squares residual {residual:.2e} m/s)")
        qd0 = a_pinv @ b
        jacobian = kinematics.ee_jacobian
        qd = qd0.copy()
        if null_basis.shape[1] > 0:
            jbar = jacobian @ null_basis
            solution = damped_least_squares(jbar, twist - jacobian @ qd0, self.policy)
            qd += null_basis @ solution.x
            self.info.sigma_min = solution.sigma_min
            self.info.damping = solution.damping
            if self.posture_gain > 0.0 and solution.row_space.shape[0] < null_basis.shape[1]:
                z = null_basis.T @ self._posture_velocity(kinematics.q)
                z -= solution.row_space.T @ (solution.row_space @ z)
                qd += null_basis @ z
        self.info.equality_residual = max(map(abs, (A @ qd - b).tolist())) if A.size else 0.0
        self.info.method = "general"
        return qd

    def _limit_velocity(self, qd: np.ndarray, kinematics: Kinematics, active: list[int]) -> np.ndarray:
        """Slow the task down, not the constraint, when a joint would exceed its limit.

        ``qd = qd_b + qd_t``: ``qd_b`` is the step for a zero twist (it holds the rows
        ``A qd_b = b``: drift feedback, feed-forward, posture) and ``qd_t`` the twist's
        part (``A qd_t = 0``). The command is ``qd_b + s qd_t`` with the largest
        ``s <= 1`` inside the limits, so the constraint still holds exactly. Only if
        ``qd_b`` alone is over a limit is everything scaled (reported in ``info.scale``
        and ``info.message``).
        """
        if not self.respect_velocity_limits:
            return qd
        # max_i |qd_i| / limit_i in plain Python beats three NumPy reductions on a few
        # joints (a NaN in qd stays there whatever the scale: solve() flags the step)
        ratio = max(map(operator.mul, map(abs, qd.tolist()), self._inverse_limit))
        if not ratio > 1.0:
            return qd
        qd = qd.copy()  # the solve below may reuse this step's buffers
        info = dataclasses.replace(self.info)
        qd_b = self._solve_active(kinematics, np.zeros(6), active).copy()
        self.info = info
        qd_t = qd - qd_b
        limit = self.velocity_limit
        scale = 1.0
        for b_i, t_i, v_i in zip(qd_b.tolist(), qd_t.tolist(), limit.tolist()):
            if t_i > 0.0:
                scale = min(scale, (v_i - b_i) / t_i)
            elif t_i < 0.0:
                scale = min(scale, (-v_i - b_i) / t_i)
        if scale >= 0.0:
            self.info.scale = scale
            return qd_b + scale * qd_t
        # the constraint's own correction is over a limit: scale it too
        ratio_b = float(np.max(np.abs(qd_b) / limit))
        self.info.scale = 0.0
        note = (f"constraint correction alone exceeds the velocity limits ({ratio_b:.2f}x): "
                "scaled, the constraint converges slower")
        self.info.message = f"{self.info.message}; {note}" if self.info.message else note
        return qd_b / ratio_b
        # max_i |qd_i| / limit_i in plain Python beats three NumPy reductions on a few
        # joints (a NaN in qd stays there whatever the scale: solve() flags the step)
        ratio = max(map(operator.mul, map(abs, qd.tolist()), self._inverse_limit))
        if ratio > 1.0:
            self.info.scale = scale = 1.0 / ratio
            qd *= scale  # qd is this step's own array
        return qd
