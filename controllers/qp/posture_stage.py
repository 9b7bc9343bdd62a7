"""Stage 2 of the lexicographic solve: the posture over the task's optimal set
(docs/design.md section 10.1).

Every ``qd_1 + N z`` holds the rows and the achieved twist as the task stage's ``qd_1``
does (``A N = 0``, ``J_e N = 0``); the posture QP is over ``z`` alone.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..base import EQUALITY_TOLERANCE, SolverError
from ..linalg import nullspace, nullspace_basis
from ..numerics import INFINITE_BOUND, RANK_TOLERANCE
from ..optimization.problem import QPSolution, QuadraticProgram

#: An inequality whose stage-1 multiplier exceeds this (normalised units), or the
#: backend's ``eps_abs`` if larger (OSQP's multipliers are only that accurate), is held
#: as an equality in stage 2: every task-optimal ``qd`` has it active (complementary
#: slackness), and left as an inequality it would make the posture QP degenerate (an
#: implicit equality: unbounded multipliers, on which proxqp stopped at a wrong point).
ACTIVE_MULTIPLIER = 1e-9

#: Misses of the task by the polished ``qd`` beyond ``qd_1``'s that still count as none
#: (m/s, normalised): rounding in the two residuals' norms.
POLISH_SLACK = 1e-12

SolveQP = Callable[[QuadraticProgram], QPSolution]


def posture_stage(stage_1: QPSolution, null_basis: np.ndarray, posture_velocity: np.ndarray,
                  task: QuadraticProgram, stacked: np.ndarray, stacked_target: np.ndarray,
                  solve: SolveQP, eps_abs: float = 0.0) -> np.ndarray:
    """``qd = qd_1 + N z``: stage 2 of the lexicographic solve (docs/design.md section 10).

    ``solve`` is the controller's backend; ``eps_abs`` its tolerance, if it has one.
    The inequalities stage 1 holds with a multiplier
    above :data:`ACTIVE_MULTIPLIER` (or the backend's ``eps_abs``) are active at
    every task-optimal ``qd``, so they join ``N``'s equalities
    (:func:`polish_on_face`, which also removes the task stage's tolerance from
    ``qd_1``). The posture QP is then over ``z`` alone, with
    the identity as Hessian: ``min 1/2 |z - N^T (qd_posture - qd_1)|^2`` under the
    other inequalities, whose bounds are widened to hold ``z = 0`` (``qd_1`` may sit
    outside by the task solve's tolerance; the base class clips that back). Where the
    unconstrained minimiser already fits, it is the answer without a solve. Where the
    posture QP fails (its rows leave a sliver or the point ``z = 0`` alone, on which
    daqp stops as infeasible and proxqp at its caps), ``z = 0`` is the answer: it holds
    every row and the task stage's optimum; only the posture is not optimised.
    """
    qd_1 = stage_1.x
    active = max(ACTIVE_MULTIPLIER, eps_abs)
    held_joints = (np.zeros(qd_1.size, dtype=bool) if stage_1.box_multipliers is None
                   else np.abs(stage_1.box_multipliers) > active)
    held_rows = (np.zeros(0 if task.rows is None else task.rows.shape[0], dtype=bool)
                 if stage_1.row_multipliers is None
                 else np.abs(stage_1.row_multipliers) > active)
    if held_joints.any() or held_rows.any():
        qd_1, null_basis = polish_on_face(stage_1, held_joints, held_rows, null_basis,
                                          task, stacked, stacked_target)
        if not null_basis.shape[1]:
            return qd_1
    target = np.dot(posture_velocity - qd_1, null_basis)
    move = np.dot(null_basis, target)
    blocks, lows, highs = [], [], []
    if task.lower is not None:
        free = np.flatnonzero(~held_joints & ((task.lower > -INFINITE_BOUND)
                                              | (task.upper < INFINITE_BOUND)))
        blocks.append(null_basis[free])
        lows.append(np.minimum(task.lower[free] - qd_1[free], 0.0))
        highs.append(np.maximum(task.upper[free] - qd_1[free], 0.0))
    if task.rows is not None:
        free = np.flatnonzero(~held_rows)
        blocks.append(task.rows[free] @ null_basis)
        lows.append(np.full(free.size, -INFINITE_BOUND))
        highs.append(np.maximum(task.rows_upper[free] - task.rows[free] @ qd_1, 0.0))
    rows = np.vstack(blocks) if blocks else np.zeros((0, target.size))
    rows_lower = np.concatenate(lows) if lows else np.zeros(0)
    rows_upper = np.concatenate(highs) if highs else np.zeros(0)
    reached = rows @ target
    if np.all(reached >= rows_lower) and np.all(reached <= rows_upper):
        return qd_1 + move
    posture = QuadraticProgram(np.eye(target.size), -target, rows=rows,
                               rows_lower=rows_lower, rows_upper=rows_upper)
    try:
        return qd_1 + null_basis @ solve(posture).x
    except SolverError:  # a sliver or a point around z = 0, which holds every row
        return qd_1


def polish_on_face(stage_1: QPSolution, held_joints: np.ndarray, held_rows: np.ndarray,
                   null_basis: np.ndarray, task: QuadraticProgram, stacked: np.ndarray,
                   stacked_target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(qd_1, N)`` on the face of the inequalities stage 1 holds (docs/design.md 10.1).

    ``N`` is narrowed to ``null(E)``, ``E`` the held rows (a joint at its bound, a
    barrier). ``qd_1`` is polished (OSQP's polish, for every backend): on the face ``F``
    of the rows, the held rows and any other inequality ``qd_1`` sits on (to
    :data:`EQUALITY_TOLERANCE`), the task stage is a least-squares problem, solved
    here exactly from ``qd_1``: ``qd_F = qd_f + Z (M Z)^+ (m - M qd_f)``, ``qd_f`` the
    nearest point of ``F`` to ``qd_1``, ``Z = null(F)``, ``m`` the stacked target. That
    removes the task solve's tolerance, which a nearly degenerate posture polytope amplifies
    (docs/design.md 10.3). ``qd_F`` moves ``qd_1`` only across ``N``, and is kept when it
    meets the other inequalities to ``EQUALITY_TOLERANCE`` and misses the task by no more
    than ``qd_1`` (+ ``POLISH_SLACK``); else ``qd_1`` stays.
    """
    qd_1 = stage_1.x
    held = ([np.eye(qd_1.size)[held_joints]] if held_joints.any() else []) + (
        [task.rows[held_rows]] if held_rows.any() else [])
    narrowed = null_basis @ nullspace_basis(np.vstack(held) @ null_basis, RANK_TOLERANCE)
    on_joints, on_rows = held_joints.copy(), held_rows.copy()
    face_rows: list[np.ndarray] = []
    face_targets: list[np.ndarray] = []
    if task.equality_matrix is not None:
        face_rows.append(task.equality_matrix)
        face_targets.append(task.equality_rhs)
    if task.lower is not None:
        at_upper = qd_1 >= task.upper - EQUALITY_TOLERANCE
        if held_joints.any():  # a held joint's side is its multiplier's
            at_upper[held_joints] = stage_1.box_multipliers[held_joints] > 0.0
        on_joints |= at_upper | (qd_1 <= task.lower + EQUALITY_TOLERANCE)
        face_rows.append(np.eye(qd_1.size)[on_joints])
        face_targets.append(np.where(at_upper, task.upper, task.lower)[on_joints])
    if task.rows is not None:
        on_rows |= task.rows @ qd_1 >= task.rows_upper - EQUALITY_TOLERANCE
        face_rows.append(task.rows[on_rows])
        face_targets.append(task.rows_upper[on_rows])
    face, face_target = np.vstack(face_rows), np.concatenate(face_targets)
    face_basis, face_pinv, _ = nullspace(face, RANK_TOLERANCE)
    on_face = qd_1 + face_pinv @ (face_target - face @ qd_1)
    task_on_face = stacked @ face_basis
    step = np.linalg.lstsq(task_on_face, stacked_target - stacked @ on_face,
                           rcond=RANK_TOLERANCE)[0]
    polished = on_face + face_basis @ step
    if polish_holds(polished, qd_1, ~on_joints, ~on_rows, face, face_target, task,
                    stacked, stacked_target):
        return polished, narrowed
    return qd_1, narrowed


def polish_holds(polished: np.ndarray, qd_1: np.ndarray, free_joints: np.ndarray,
                 free_rows: np.ndarray, face: np.ndarray, face_target: np.ndarray,
                 task: QuadraticProgram, stacked: np.ndarray, stacked_target: np.ndarray
                 ) -> bool:
    """Whether the polished ``qd`` holds its face and the other inequalities to
    ``EQUALITY_TOLERANCE`` and misses the task by no more than ``qd_1`` (+
    ``POLISH_SLACK``)."""
    if np.max(np.abs(face @ polished - face_target)) > EQUALITY_TOLERANCE:
        return False  # the face's rows are not consistent
    if task.lower is not None and not (
            np.all(polished[free_joints] >= task.lower[free_joints] - EQUALITY_TOLERANCE)
            and np.all(polished[free_joints] <= task.upper[free_joints] + EQUALITY_TOLERANCE)):
        return False
    if task.rows is not None and free_rows.any() and np.any(
            task.rows[free_rows] @ polished > task.rows_upper[free_rows] + EQUALITY_TOLERANCE):
        return False
    return bool(np.linalg.norm(stacked @ polished - stacked_target)
                <= np.linalg.norm(stacked @ qd_1 - stacked_target) + POLISH_SLACK)

