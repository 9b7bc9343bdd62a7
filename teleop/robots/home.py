"""The home pose of a robot: inside its joint limits by a margin, away from singularities
(docs/design.md section 6.1).

A robot loaded from a URDF without a ``q_home`` gets :func:`default_home`: Pinocchio's
neutral configuration moved into the margin, then a seeded local search that maximises
:class:`Conditioning.worst`, the smallest singular value (over the generic rank) of the
end-effector Jacobian ``J_e``, of the rows ``A`` of a hole on each constrained link and of
the constrained task Jacobian ``J_e N`` (``N = null(A)``). A home given by the user is
checked instead (:func:`check_home`): one warning names what is wrong with it.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import pinocchio as pin

from constraints import Hole
from constraints.base import RobotLike as ConstraintRobot
from controllers.linalg import DampingPolicy, nullspace_basis

__all__ = ["HOME_MARGIN", "HOLE_DISTANCE", "SINGULAR_BELOW", "Conditioning", "HomeMeasure",
           "HomeWarning", "JointBox", "check_home", "default_home", "joint_box",
           "sampling_bounds"]

#: The fraction of each bounded joint's range a home keeps from each bound.
HOME_MARGIN = 0.1
#: Where the home's hole sits on each constrained link (m along its axis): the UI's default.
HOLE_DISTANCE = 0.08
#: A home whose :attr:`Conditioning.worst` is below this is singular: the CJM's default
#: ``singular_threshold``, where its damping sets in (paper eq 35).
SINGULAR_BELOW = DampingPolicy().threshold
#: Limits at or beyond this magnitude count as unbounded (Pinocchio uses +-DBL_MAX).
UNBOUNDED = 1e10
#: A margin short of ``HOME_MARGIN`` by less than this is rounding (a default home saved
#: to a scene and loaded back as a given one sits at the margin to the last bit).
_MARGIN_ROUNDING = 1e-9

#: The local search: candidates per round, first step (rad, or the range's share of pi
#: for a prismatic joint), rounds at most, smallest step. Seeded: the same URDF always
#: gets the same home.
_CANDIDATES = 8
_FIRST_STEP = 0.4
_ROUNDS = 60
_SMALLEST_STEP = 0.01
_SEED = 0
#: Singular values above this share of the largest count towards a matrix's rank.
_RANK_TOLERANCE = 1e-6
#: Configurations the generic ranks are taken over (the largest rank seen).
_RANK_SAMPLES = 4


class HomeRobot(ConstraintRobot, Protocol):
    """What the home search needs from a robot (``teleop.Robot`` satisfies it)."""

    @property
    def ee_frames(self) -> tuple[str, ...]: ...
    @property
    def constrained_links(self) -> tuple[str, ...]: ...


class HomeWarning(UserWarning):
    """A given home pose is near a joint limit or singular (see :func:`check_home`)."""


def sampling_bounds(model: pin.Model) -> tuple[np.ndarray, np.ndarray]:
    """Position limits with unbounded entries replaced by -pi / +pi."""
    lower = np.array(model.lowerPositionLimit, dtype=float)
    upper = np.array(model.upperPositionLimit, dtype=float)
    free = ~np.isfinite(lower) | ~np.isfinite(upper) | (np.abs(lower) >= UNBOUNDED) \
        | (np.abs(upper) >= UNBOUNDED)
    lower[free], upper[free] = -np.pi, np.pi
    return lower, upper


@dataclass(frozen=True)
class JointBox:
    """The bounded coordinates of a model: revolute and prismatic joints with finite
    limits (continuous joints, planar and free joints have none).

    Attributes
    ----------
    q_index, v_index : (k,) their configuration and velocity indices.
    lower, upper : (k,) their limits.
    names : (k,) their joint names.
    """

    q_index: np.ndarray
    v_index: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    names: tuple[str, ...]

    def inner(self, margin: float = HOME_MARGIN) -> tuple[np.ndarray, np.ndarray]:
        """The box shrunk by ``margin`` of each range at both ends."""
        span = self.upper - self.lower
        return self.lower + margin * span, self.upper - margin * span

    def margins(self, q: np.ndarray) -> np.ndarray:
        """Each coordinate's distance to its nearer bound, as a share of its range."""
        x = q[self.q_index]
        return np.minimum(x - self.lower, self.upper - x) / (self.upper - self.lower)


def joint_box(model: pin.Model) -> JointBox:
    """The bounded coordinates of ``model`` (:class:`JointBox`)."""
    q_index, v_index, names = [], [], []
    for joint in range(1, model.njoints):
        if model.nqs[joint] != 1 or model.nvs[joint] != 1:
            continue
        i = model.idx_qs[joint]
        lower, upper = model.lowerPositionLimit[i], model.upperPositionLimit[i]
        if np.isfinite(lower) and np.isfinite(upper) and max(abs(lower), abs(upper)) < UNBOUNDED \
                and upper > lower:
            q_index.append(i)
            v_index.append(model.idx_vs[joint])
            names.append(model.names[joint])
    q_indices = np.array(q_index, dtype=int)
    return JointBox(q_indices, np.array(v_index, dtype=int),
                    np.array(model.lowerPositionLimit[q_indices], dtype=float),
                    np.array(model.upperPositionLimit[q_indices], dtype=float), tuple(names))


@dataclass(frozen=True)
class Conditioning:
    """How far a configuration is from singular: the smallest singular values, over each
    matrix's generic rank, of the EE Jacobian ``J_e`` (LOCAL, stacked over the EEs), of
    the hole rows ``A`` and of the constrained task Jacobian ``J_e N``. None for a
    matrix the robot does not have (no constrained link) or that is zero everywhere."""

    ee: float | None
    hole_rows: float | None
    constrained: float | None

    @property
    def worst(self) -> float:
        """The smallest of them (infinite when there is none)."""
        return min((x for x in (self.ee, self.hole_rows, self.constrained) if x is not None),
                   default=np.inf)

    def describe(self) -> str:
        names = ("EE Jacobian", "hole rows", "constrained Jacobian")
        return ", ".join(f"{name} {value:.3g}" for name, value in
                         zip(names, (self.ee, self.hole_rows, self.constrained))
                         if value is not None)


def _sigma(matrix: np.ndarray, rank: int) -> float | None:
    """The ``rank``-th largest singular value of ``matrix``; None for rank 0."""
    if rank == 0:
        return None
    return float(np.linalg.svd(matrix, compute_uv=False)[rank - 1])


def _rank(matrix: np.ndarray) -> int:
    if matrix.size == 0:
        return 0
    values = np.linalg.svd(matrix, compute_uv=False)
    return int(np.sum(values > _RANK_TOLERANCE * max(1.0, float(values[0]))))


class HomeMeasure:
    """:class:`Conditioning` of a robot at any configuration, with a hole
    ``HOLE_DISTANCE`` m along each constrained link where that link is.

    The generic ranks (the rank where the robot is not singular: a hole on a link with
    four joints before it leaves the EE 5 DoF, so ``J_e N`` never has rank 6) are the
    largest seen at ``_RANK_SAMPLES`` seeded configurations inside the margin.
    """

    def __init__(self, robot: HomeRobot) -> None:
        self.robot = robot
        self.model = robot.model
        self.data = self.model.createData()
        self.ee_ids = [self.model.getFrameId(name) for name in robot.ee_frames]
        self.links = tuple(robot.constrained_links)
        self.box = joint_box(self.model)
        rng = np.random.default_rng(_SEED)
        samples = [self._matrices(self._random(rng)) for _ in range(_RANK_SAMPLES)]
        ee_rank = max(_rank(ee) for ee, _, _ in samples)
        #: the generic ranks of J_e, A and J_e N (0: the robot has no such matrix)
        self.ranks = ((ee_rank, 0, 0) if not self.links else
                      (ee_rank, *(max(_rank(m[k]) for m in samples) for k in (1, 2))))

    def _random(self, rng: np.random.Generator) -> np.ndarray:
        lower, upper = sampling_bounds(self.model)
        q = rng.uniform(lower, upper)
        inner_lower, inner_upper = self.box.inner()
        q[self.box.q_index] = rng.uniform(inner_lower, inner_upper)
        return pin.normalize(self.model, q)

    def _matrices(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``J_e``, ``A`` and ``J_e N`` at ``q``."""
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        ee = np.vstack([pin.getFrameJacobian(model, data, i, pin.LOCAL) for i in self.ee_ids])
        holes = [Hole.on_link(self.robot, q, distance=HOLE_DISTANCE, link=link)
                 for link in self.links]
        rows = (np.vstack([hole.rows(model, data)[0] for hole in holes]) if holes
                else np.zeros((0, model.nv)))
        null_basis = nullspace_basis(rows)
        return ee, rows, ee @ null_basis

    def __call__(self, q: np.ndarray) -> Conditioning:
        return Conditioning(*(_sigma(matrix, rank)
                              for matrix, rank in zip(self._matrices(q), self.ranks)))


def _into_margin(box: JointBox, q: np.ndarray) -> np.ndarray:
    """``q`` with its bounded coordinates clipped into ``box.inner()``."""
    lower, upper = box.inner()
    q = q.copy()
    q[box.q_index] = np.clip(q[box.q_index], lower, upper)
    return q


def _moving_velocities(model: pin.Model, frame_ids: Sequence[int]) -> np.ndarray:
    """The velocity indices of the joints that move any of ``frame_ids``."""
    joints = {j for frame in frame_ids for j in model.supports[model.frames[frame].parentJoint]}
    return np.array([v for j in sorted(joints - {0})
                     for v in range(model.idx_vs[j], model.idx_vs[j] + model.nvs[j])], dtype=int)


def default_home(robot: HomeRobot, start: np.ndarray) -> np.ndarray:
    """The home of a robot without a given one (docs/design.md section 6.1).

    ``start`` (Pinocchio's neutral configuration, normally) is moved into the margin:
    each bounded coordinate at least ``HOME_MARGIN`` of its range from each bound. Then a
    seeded (1 + 8) search over the joints that move an EE or a constrained link: each
    round draws 8 Gaussian steps around the best configuration so far, each kept in the
    margin; the best replaces it when it raises :attr:`Conditioning.worst`, else the
    step halves. It stops when the step is below ``_SMALLEST_STEP`` or after ``_ROUNDS``
    rounds: a local maximum near the neutral pose, the same for the same URDF.
    """
    measure = HomeMeasure(robot)
    model, box = measure.model, measure.box
    moving = _moving_velocities(model, [*measure.ee_ids,
                                        *(model.getFrameId(link) for link in measure.links)])
    scale = np.ones(model.nv)
    scale[box.v_index] = np.minimum(box.upper - box.lower, np.pi) / np.pi
    best = _into_margin(box, start)
    best_value = measure(best).worst
    rng = np.random.default_rng(_SEED)
    step = _FIRST_STEP
    for _ in range(_ROUNDS):
        if step < _SMALLEST_STEP:
            break
        improved = False
        for _ in range(_CANDIDATES):
            v = np.zeros(model.nv)
            v[moving] = step * scale[moving] * rng.standard_normal(moving.size)
            candidate = _into_margin(box, pin.integrate(model, best, v))
            value = measure(candidate).worst
            if value > best_value:
                best, best_value, improved = candidate, value, True
        if not improved:
            step /= 2.0
    return best


def check_home(robot: HomeRobot, q: np.ndarray, what: str = "q_home") -> None:
    """Warn (one :class:`HomeWarning`) when ``q`` has a joint within ``HOME_MARGIN`` of its
    range from a bound, or is singular (:attr:`Conditioning.worst` below
    ``SINGULAR_BELOW``), naming the joints and the matrices."""
    box = joint_box(robot.model)
    margins = box.margins(q)
    problems = []
    near = np.flatnonzero(margins < HOME_MARGIN - _MARGIN_ROUNDING)
    if near.size:
        problems.append(f"near the joint limits (less than {HOME_MARGIN:.0%} of the range from "
                        "a bound: " + ", ".join(f"{box.names[i]} at {margins[i]:.1%}"
                                                for i in near) + ")")
    conditioning = HomeMeasure(robot)(q)
    if conditioning.worst < SINGULAR_BELOW:
        hole = (f" for a hole {HOLE_DISTANCE} m along {', '.join(robot.constrained_links)}"
                if robot.constrained_links else "")
        problems.append(f"singular{hole} (smallest singular values: {conditioning.describe()}; "
                        f"the CJM damps below {SINGULAR_BELOW:g})")
    if problems:
        warnings.warn(f"{what} is {'; and '.join(problems)}: the robot may start stuck; "
                      "leave q_home out for a home inside the limits and away from "
                      "singularities", HomeWarning, stacklevel=3)
