"""Joint limits with acceleration limits: saturation around the previous command,
docs/design.md section 9.1.

With acceleration limits the joint box is a narrow window around the previous command
``qd_prev``. SNS's line ``base + s direction`` starts at the minimum-norm rows solution,
centred on zero, and crosses that window only by chance. Here every point is reached by
walking from ``qd_prev`` (brought into the box) and never leaving the box:

0. a joint whose box excludes ``qd_prev`` is held at the bound nearest it;
1. **rows**: walk towards ``point + A_F^+ (b - A point)`` over the free joints ``F``;
   where a free joint reaches its bound, hold it there and walk again over the others;
   where the free joints can reduce the residual no further, release a held joint whose
   bound pushes the wrong way (the gradient ``A^T (A point - b)`` points inside its box):
   an active-set bounded least squares, so the rows hold exactly whenever some command in
   the box holds them, and otherwise keep the box's least residual through level 2;
2. **task**: the same active set on ``|J qd - V|^2 + |D qd|^2`` under the rows, ``D`` the
   CJM's damping rows of the whole problem (:func:`~controllers.optimization.task_damping.
   task_damping`, the QP's too: docs/design.md 10.7): walk towards the rows-exact
   least-squares point over the free joints, hold the joint that stops the walk, and once
   that point is reached release a held joint whose reduced gradient points into its
   box. It ends at the box's optimum of the damped task, the QP's first stage.

Only a joint that can move is released: one with room in its box beyond rounding and, at
level 2, whose column of the rows the free joints' columns give (:func:`column_outside`);
releasing another held it again at once, a cycle to the iteration cap.

Every iterate of level 2 is a convex combination of points that hold the rows and lies in
the box, and the result moves continuously with ``q``, the twist and the box.

**Warm start** (:func:`saturate_from_held`). After a period this saturation gave with the
rows held, the next period may first hold the same joints at the same sides of its own box
and solve the rows and the damped task over the others: where that point has the free
joints inside the box and no held joint's reduced gradient pointing into its box (the
optimum's conditions) and the optimum is unique (``[J N; D N]`` of full column rank), it
is the point level 2 ends at, and level 1 and the walk are not run. Where the last
period held a joint and neither period damps, it is tried before the unsaturated form,
which it then replaces too (docs/design.md 9.1 says why that is the same command).
The rows are the equalities alone: with barriers or collision rows the step runs as above.
"""

from __future__ import annotations

import numpy as np

from ..base import TWIST_TOLERANCE
from ..linalg import DampingPolicy, nullspace
from ..numerics import RANK_TOLERANCE
from ..optimization.task_damping import TaskDamping, task_damping
from .saturation import Saturation, gap_to_bound, solve_over_free
from .tolerances import (AT_BOUND, BOX_MARGIN, RELEASE_TOLERANCE, ROWS_TOLERANCE,
                         STILL_DIRECTION)

#: The damping is in the task's rows (``D``): the least squares over the free joints is exact.
UNDAMPED = DampingPolicy(0.0, 0.0, 0.0)


def saturate_around_previous(rows: np.ndarray, rows_rhs: np.ndarray, jacobian: np.ndarray,
                             twist: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                             policy: DampingPolicy, previous: np.ndarray) -> Saturation:
    """``qd`` inside ``[lower, upper]`` reached from ``previous``: the rows ``A qd = b``
    first (exactly when the box allows it), the damped twist second (module docstring)."""
    nv = jacobian.shape[1]
    point = np.minimum(np.maximum(previous, lower), upper)
    free = ((previous >= lower - BOX_MARGIN * (1.0 + np.abs(lower)))  # outside beyond rounding:
            & (previous <= upper + BOX_MARGIN * (1.0 + np.abs(upper))))  # held (step 0)
    point, free, rows_scale = walk_to_rows(rows, rows_rhs, lower, upper, point, free)
    if rows_scale < 1.0:  # the task keeps the rows' least residual (the QP's recovery, 10.7)
        rows_rhs = rows @ point
    damping = task_damping(rows, jacobian, policy)
    task, task_rhs = _walk_task(jacobian, twist, damping)
    limiting_joint = -1
    for _ in range(3 * nv + 1):
        if free.any():
            split = solve_over_free(rows, rows_rhs, task, task_rhs, free,
                                    np.where(free, 0.0, point), UNDAMPED)
            if split.rows_residual > ROWS_TOLERANCE:
                break  # the held joints leave the rows no freedom
            point, joint = _walk(point, split.base + split.direction, lower, upper, free)
            if joint >= 0:
                free[joint] = False
                limiting_joint = joint if limiting_joint < 0 else limiting_joint
                continue
        joint = _task_wrong_side(rows, task, task_rhs, point, lower, upper, free)
        if joint < 0:
            break  # the box's optimum
        free[joint] = True
    return _walk_result(point, rows_scale, free, limiting_joint, jacobian, twist,
                        damping.sigma_min, damping.damping)


def saturate_from_held(rows: np.ndarray, rows_rhs: np.ndarray, jacobian: np.ndarray,
                       twist: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                       policy: DampingPolicy, sides: np.ndarray, limiting_joint: int,
                       undamped_only: bool = False) -> tuple[Saturation | None, bool]:
    """The warm start: the joints of ``sides`` (-1: at the lower bound, +1: the upper,
    0: free; the previous period's) held at those sides of this box, the rows exactly and
    the damped task over the others. That point is level 2's end when it satisfies the
    optimum's conditions (the free joints in the box, no held joint's reduced gradient
    pointing into its box) and the optimum is unique (``[J N; D N]`` of full column rank):
    the saturation and True; else None, and the walk runs (docs/design.md 9.1), with
    whether the conditions were decided (False: the optimum not unique, or
    ``undamped_only`` and lambda positive or the walk's unconstrained optimum, the general
    form's command, inside the box). ``limiting_joint`` (the previous period's) is
    reported while it is held, else the first held joint."""
    damping = task_damping(rows, jacobian, policy)
    if not damping.null_basis.shape[1] or damping.rank < damping.null_basis.shape[1]:
        return None, False  # not unique: the walk's path decides
    task, task_rhs = _walk_task(jacobian, twist, damping)
    if undamped_only and (damping.damping > 0.0 or _optimum_fits_box(
            rows, rows_rhs, task, task_rhs, lower, upper)):
        return None, False
    free = sides == 0
    held = np.where(sides < 0, lower, np.where(sides > 0, upper, 0.0))
    split = solve_over_free(rows, rows_rhs, task, task_rhs, free, held, UNDAMPED)
    if split.rows_residual > ROWS_TOLERANCE:
        return None, True
    point = split.base + split.direction
    if not np.all((point[free] >= lower[free]) & (point[free] <= upper[free])):
        return None, True
    if _task_wrong_side(rows, task, task_rhs, point, lower, upper, free) >= 0:
        return None, True
    if limiting_joint < 0 or free[limiting_joint]:
        limiting_joint = int(np.flatnonzero(~free)[0]) if not free.all() else -1
    return _walk_result(point, 1.0, free, limiting_joint, jacobian, twist,
                        damping.sigma_min, damping.damping), True


def _optimum_fits_box(rows: np.ndarray, rows_rhs: np.ndarray, task: np.ndarray,
                      task_rhs: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> bool:
    """Whether level 2's unconstrained optimum (every joint free) holds the rows and fits
    the box."""
    every = np.ones(lower.size, dtype=bool)
    split = solve_over_free(rows, rows_rhs, task, task_rhs, every, np.zeros(lower.size),
                            UNDAMPED)
    optimum = split.base + split.direction
    return (split.rows_residual <= ROWS_TOLERANCE
            and bool(np.all((optimum >= lower) & (optimum <= upper))))


def held_sides(saturation: Saturation, lower: np.ndarray, upper: np.ndarray) -> np.ndarray | None:
    """The warm start's sides of ``saturation``'s held joints (-1 nearer the lower bound,
    +1 the upper, 0 free); None when it is no start (the rows degraded, or no joint free)."""
    if saturation.rows_scale < 1.0 or len(saturation.saturated) == lower.size:
        return None
    sides = np.zeros(lower.size, dtype=int)
    qd = saturation.qd
    for joint in saturation.saturated:
        sides[joint] = -1 if qd[joint] - lower[joint] <= upper[joint] - qd[joint] else 1
    return sides


def _walk_task(jacobian: np.ndarray, twist: np.ndarray,
               damping: TaskDamping) -> tuple[np.ndarray, np.ndarray]:
    """Level 2's least squares ``[J; D] qd ~ [V; 0]``."""
    return (np.vstack([jacobian, damping.rows]),
            np.concatenate([twist, np.zeros(damping.rows.shape[0])]))


def walk_to_rows(rows: np.ndarray, rows_rhs: np.ndarray, lower: np.ndarray,
                 upper: np.ndarray, point: np.ndarray,
                 free: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Level 1: ``point`` moved inside the box until ``rows point = rows_rhs`` or no move
    in the box reduces ``|rows point - rows_rhs|``; the point, the free joints and the
    fraction ``r`` of the starting residual removed (1: the rows hold)."""
    point, free = point.copy(), free.copy()
    nv = point.size
    initial = float(np.max(np.abs(rows_rhs - rows @ point), initial=0.0))
    for _ in range(3 * nv + 1):
        residual_vector = rows_rhs - rows @ point
        if float(np.max(np.abs(residual_vector), initial=0.0)) <= ROWS_TOLERANCE:
            return point, free, 1.0
        correction = np.zeros(nv)
        if free.any():
            _, rows_pinv, _ = nullspace(rows[:, free])
            correction[free] = rows_pinv @ residual_vector
        if float(np.max(np.abs(rows @ correction))) <= ROWS_TOLERANCE:
            joint = _wrong_side(rows, residual_vector, point, lower, upper, free)
            if joint < 0:
                break  # the least-squares point of the box: the rows cannot hold
            free[joint] = True
            continue
        point, joint = _walk(point, point + correction, lower, upper, free)
        if joint >= 0:
            free[joint] = False
    residual = float(np.max(np.abs(rows_rhs - rows @ point), initial=0.0))
    if residual <= ROWS_TOLERANCE:
        return point, free, 1.0
    return point, free, max(0.0, 1.0 - residual / initial)


def _wrong_side(rows: np.ndarray, residual: np.ndarray, point: np.ndarray,
                lower: np.ndarray, upper: np.ndarray, free: np.ndarray) -> int:
    """The held joint whose release reduces the rows' residual most at first order (-1:
    none): the gradient of ``|rows qd - rhs|^2 / 2``, ``-rows^T residual``, points into
    its box."""
    return _inward(-(rows.T @ residual), point, lower, upper, free, ROWS_TOLERANCE)


def _task_wrong_side(rows: np.ndarray, task: np.ndarray, task_rhs: np.ndarray,
                     point: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                     free: np.ndarray) -> int:
    """The held joint whose release reduces the damped task's error most at first order
    under the rows (-1: none). With ``g = T^T (T qd - r)`` and the rows' multipliers
    ``mu = -(A_F^T)^+ g_F`` of the free joints' stationarity, joint ``i``'s reduced
    gradient is ``g_i + a_i^T mu = g_i - (A_F^+ a_i)^T g_F``."""
    gradient = task.T @ (task @ point - task_rhs)
    reduced = gradient.copy()
    if rows.shape[0]:
        weights = np.zeros((int(free.sum()), rows.shape[1]))  # A_F^+ a_i, per joint i
        if free.any():
            _, rows_pinv, _ = nullspace(rows[:, free])
            weights = rows_pinv @ rows
        reduced -= weights.T @ gradient[free]
        reduced[column_outside(rows, weights, free)] = 0.0
    tolerance = RELEASE_TOLERANCE * (1.0 + float(np.max(np.abs(gradient))))
    return _inward(reduced, point, lower, upper, free, tolerance)


def column_outside(rows: np.ndarray, weights: np.ndarray, free: np.ndarray) -> np.ndarray:
    """The joints whose column ``a_i`` of the rows the free joints' columns cannot give:
    ``|A_F A_F^+ a_i - a_i|_2`` above the rank cut of ``[A_F a_i]``,
    ``RANK_TOLERANCE max(1, |a_j|_2)`` over its columns (at most the cut of
    :func:`controllers.linalg.nullspace`, ``RANK_TOLERANCE max(1, sigma_max)``: a column
    the solve over ``F + i`` would count is never taken for one it would not), with
    ``weights = A_F^+ A``. Such a joint cannot move alone while the rows hold: no direction
    of the walk releases it, and its reduced gradient is not defined (the rows'
    multipliers are not unique along the component), so releasing it would hold it again
    at once, or leave it free and fixed by the rows (docs/design.md 9.1)."""
    reached = rows[:, free] @ weights
    norms = np.linalg.norm(rows, axis=0)
    largest = np.maximum(float(np.max(norms[free], initial=0.0)), norms)
    tolerance = RANK_TOLERANCE * np.maximum(1.0, largest)
    return np.linalg.norm(reached - rows, axis=0) > tolerance


def _inward(gradient: np.ndarray, point: np.ndarray, lower: np.ndarray, upper: np.ndarray,
            free: np.ndarray, tolerance: float) -> int:
    """The held joint at a bound whose ``-gradient`` points into its box the most, beyond
    ``tolerance`` (-1: none); of joints within ``tolerance`` of the most (joints that move
    alike, as two with one axis), the first, whatever the last bits of their gradients. A
    joint without room in its box beyond rounding (a window of width zero,
    :func:`controllers.cjm.saturation.gap_to_bound`) is never released: the walk would hold
    it again at once, a cycle to the iteration cap."""
    noise = float(np.max(np.abs(point), initial=0.0))
    room_down = np.array([gap_to_bound(bound, value, noise) < 0.0
                          for bound, value in zip(lower.tolist(), point.tolist())])
    room_up = np.array([gap_to_bound(bound, value, noise) > 0.0
                        for bound, value in zip(upper.tolist(), point.tolist())])
    inward = np.where((point >= upper) & room_down, gradient,
                      np.where((point <= lower) & room_up, -gradient, -np.inf))
    inward[free] = -np.inf
    most = float(np.max(inward))
    if not most > tolerance:
        return -1
    return int(np.flatnonzero(inward >= most - tolerance)[0])


def _walk(point: np.ndarray, goal: np.ndarray, lower: np.ndarray, upper: np.ndarray,
          free: np.ndarray) -> tuple[np.ndarray, int]:
    """``point + t (goal - point)`` with the largest ``t`` in [0, 1] that keeps the free
    joints in the box (the ratio test), and the joint that stops it, placed exactly on
    the bound it reaches (-1: the goal reached). A joint at its bound up to rounding
    (:func:`controllers.cjm.saturation.gap_to_bound`) stops the walk at once; of joints
    whose reaches tie to :data:`AT_BOUND` (joints that move alike, as two with one axis),
    the first stops it, whatever the last bits of their reaches (the others end on their
    bounds by the final clip)."""
    move = goal - point
    noise = float(np.max(np.abs(point), initial=0.0))
    still = max(STILL_DIRECTION, AT_BOUND * float(np.max(np.abs(move), initial=0.0)))
    reaches: dict[int, float] = {}
    for i in np.flatnonzero(free & (np.abs(move) > still)).tolist():
        side = upper[i] if move[i] > 0.0 else lower[i]
        reach = max(gap_to_bound(side, point[i], noise) / move[i], 0.0)
        if reach < 1.0:
            reaches[i] = reach
    fraction, joint, bound = 1.0, -1, 0.0
    if reaches:
        smallest = min(reaches.values())
        joint = next(i for i, reach in reaches.items() if reach <= smallest + AT_BOUND)
        fraction = reaches[joint]
        bound = upper[joint] if move[joint] > 0.0 else lower[joint]
    moved = np.where(free, point + fraction * move, point)
    if joint >= 0:
        moved[joint] = bound
    return np.minimum(np.maximum(moved, lower), upper), joint


def _walk_result(qd: np.ndarray, rows_scale: float, free: np.ndarray, limiting_joint: int,
                 jacobian: np.ndarray, twist: np.ndarray, sigma_min: float,
                 damping: float) -> Saturation:
    """The walk's command and what it gives of the twist: all of it when ``J qd`` meets
    the twist to the twist tolerance (``s = 1``), else the scale ``s`` of the twist along
    which ``J qd`` lies when it does (``scaled``), else a least-squares task. The share
    ``J qd . V / |V|^2`` of a met twist is 1 only up to rounding: the status must not
    depend on it (docs/design.md 9.1)."""
    achieved = jacobian @ qd
    tolerance = TWIST_TOLERANCE * (1.0 + float(np.max(np.abs(twist), initial=0.0)))
    twist_norm = float(twist @ twist)
    if float(np.max(np.abs(achieved - twist), initial=0.0)) <= tolerance or twist_norm == 0.0:
        task_scale = 1.0
    else:
        task_scale = min(max(float(achieved @ twist) / twist_norm, 0.0), 1.0)
    missed = float(np.max(np.abs(achieved - task_scale * twist), initial=0.0)) > tolerance
    return Saturation(qd, task_scale, rows_scale, tuple(np.flatnonzero(~free).tolist()),
                      limiting_joint, missed, sigma_min, damping)
