"""Home through the constraints: a joint path from where the robot is to its home
configuration whose every step keeps the constraint rows (docs/design.md section 20.3).

The path is the posture's gradient flow on the constraints, planned in the model::

    q_{k+1} = q_k (+) (s_k N N^T (q_home (-) q_k) + A^+ b / (2 K))
    N = null(A),  A qd = b the equality rows at q_k (b = -K e: half the error corrected),
    s_k = min(1, step / max |N N^T (q_home (-) q_k)|)   at most ``step`` rad a sample

It decreases ``|q_home (-) q|^2`` among the configurations that hold the rows; it ends
at home (``reached``), or where it stalls and says why: home itself breaks a constraint
(the port is not where the link passes at home), a joint limit or a one-sided
constraint is in the way, or the flow stops at a local minimum. The loop follows the
EE poses along the path in full pose (:func:`path_poses`), which on a chain with no
spare freedom fixes the joints along it; the posture takes any that are left.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin

from constraints import Constraint

from .naming import constraint_names

#: How close (rad, largest joint) the path's end must be to home to count as reached.
HOME_TOLERANCE = 1e-4
#: The largest joint motion (rad or m) of one sample of the path.
PATH_STEP = 2e-3
#: A constraint broken at home by more than this (m) makes home unreachable.
CONSTRAINT_TOLERANCE = 1e-4
#: The most samples a path takes (``ceil(2 pi / PATH_STEP)`` per joint would be a full turn).
MAX_SAMPLES = 20000


@dataclass(frozen=True)
class HomePath:
    """A path towards home: its configurations (samples x nq, the first where the robot
    is, the last home itself when it is ``reached``), whether it ends at home, and why
    not in words (empty when it does)."""

    configurations: np.ndarray
    reached: bool
    words: str


def _rows(model: pin.Model, data: pin.Data, q: np.ndarray,
          constraints: Sequence[Constraint], frames: Sequence[int]) -> tuple[np.ndarray, np.ndarray]:
    """The equality rows ``A qd = b`` at ``q`` (empty without equalities)."""
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    pairs = [constraint.rows(model, data, frame) for constraint, frame in zip(constraints, frames)
             if constraint.is_equality]
    if not pairs:
        return np.zeros((0, model.nv)), np.zeros(0)
    return np.vstack([A for A, _ in pairs]), np.concatenate([b for _, b in pairs])


def _broken_at(model: pin.Model, data: pin.Data, q: np.ndarray,
               constraints: Sequence[Constraint], frames: Sequence[int],
               tolerance: float) -> list[tuple[int, float]]:
    """``(index, violation)`` of each constraint broken at ``q`` beyond ``tolerance``."""
    pin.framesForwardKinematics(model, data, q)
    return [(i, violation) for i, (constraint, frame) in enumerate(zip(constraints, frames))
            if (violation := constraint.violation(data.oMf[frame])) > tolerance]


def plan_home_path(model: pin.Model, q: np.ndarray, home: np.ndarray,
                   constraints: Sequence[Constraint], frames: Sequence[int],
                   step: float = PATH_STEP, max_samples: int = MAX_SAMPLES) -> HomePath:
    """The path of the module docstring from ``q`` to ``home`` holding ``constraints``
    (on frames ``frames``); position limits and one-sided constraints end it where they
    would be crossed."""
    data = model.createData()
    names = constraint_names(constraints)
    broken = _broken_at(model, data, home, constraints, frames, CONSTRAINT_TOLERANCE)
    if broken:
        index, violation = broken[0]
        return HomePath(np.array([q]), False,
                        f"home is off {names[index]} by {1e3 * violation:.1f} mm (it was placed "
                        f"away from the home pose): home cannot be reached while it holds; "
                        f"remove it to go home")
    path = [np.array(q, dtype=float)]
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for _ in range(max_samples):
        current = path[-1]
        A, b = _rows(model, data, current, constraints, frames)
        towards = pin.difference(model, current, home)
        if np.max(np.abs(towards)) < HOME_TOLERANCE:  # the last sample home itself
            return HomePath(np.array(path[:-1] + [np.array(home, dtype=float)]), True, "")
        if A.shape[0]:
            _, singular, vt = np.linalg.svd(A)
            rank = int(np.sum(singular > 1e-10 * max(1.0, singular[0])))
            basis = vt[rank:].T
            flow = basis @ (basis.T @ towards)
            gains = [constraint.gain for constraint in constraints if constraint.is_equality]
            gain = max(gains)
            correction = (np.linalg.pinv(A) @ b) / (2.0 * gain) if gain > 0.0 else 0.0 * towards
        else:
            flow, correction = towards, 0.0 * towards
        largest = float(np.max(np.abs(flow)))
        if largest < 1e-3 * HOME_TOLERANCE:
            return HomePath(np.array(path), False,
                            f"the way home through the constraints stops "
                            f"{np.max(np.abs(towards)):.3f} rad from home (no joint motion that "
                            f"holds them brings it nearer)")
        nxt = pin.integrate(model, current, min(1.0, step / largest) * flow + correction)
        outside = np.flatnonzero((nxt < lower) | (nxt > upper))
        if outside.size:
            return HomePath(np.array(path), False,
                            f"the way home through the constraints crosses the limit of joint "
                            f"{model.names[int(_joint_of(model, outside[0]))]}")
        barrier = _broken_at(model, data, nxt,
                             [c for c in constraints if not c.is_equality],
                             [f for c, f in zip(constraints, frames) if not c.is_equality], 0.0)
        if barrier:
            inequalities = [name for c, name in zip(constraints, names) if not c.is_equality]
            return HomePath(np.array(path), False,
                            f"{inequalities[barrier[0][0]]} is in the way home")
        path.append(nxt)
    return HomePath(np.array(path), False, f"the way home takes more than {max_samples} "
                    f"steps of {step:g} rad")


def _joint_of(model: pin.Model, index: int) -> int:
    """The joint whose configuration holds entry ``index`` of ``q``."""
    return next(joint for joint in range(1, model.njoints)
                if model.idx_qs[joint] <= index < model.idx_qs[joint] + model.nqs[joint])


def path_poses(model: pin.Model, configurations: np.ndarray,
               frames: Sequence[int]) -> list[list[pin.SE3]]:
    """The world poses of ``frames`` (the EEs) at each configuration of a path."""
    data = model.createData()
    poses = []
    for q in configurations:
        pin.framesForwardKinematics(model, data, q)
        poses.append([data.oMf[frame].copy() for frame in frames])
    return poses


def path_times(model: pin.Model, configurations: np.ndarray, poses: list[list[pin.SE3]],
               max_linear_speed: float, max_angular_speed: float,
               fraction: float = 0.8) -> np.ndarray:
    """When the loop's targets reach each sample of a path (s from its start): each
    segment at ``fraction`` of the loop's caps (the EEs' linear and angular speeds) and of
    the joints' velocity limits, whichever is slowest."""
    limits = np.where(np.isfinite(model.velocityLimit) & (model.velocityLimit > 0.0),
                      model.velocityLimit, np.inf)
    times = [0.0]
    for k in range(1, len(configurations)):
        joints = np.abs(pin.difference(model, configurations[k - 1], configurations[k]))
        linear = max(float(np.linalg.norm(b.translation - a.translation))
                     for a, b in zip(poses[k - 1], poses[k]))
        angular = max(float(np.linalg.norm(pin.log3(a.rotation.T @ b.rotation)))
                      for a, b in zip(poses[k - 1], poses[k]))
        times.append(times[-1] + max(float(np.max(joints / limits)),
                                     linear / max_linear_speed,
                                     angular / max_angular_speed) / fraction)
    return np.array(times)
