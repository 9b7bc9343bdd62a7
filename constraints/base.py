"""Common base of the kinematic constraints on a point of the robot's chain.

Notation (docs/design.md sections 2-3, paper sections 4-5). ``F_a`` is the frame of the link
that carries the constrained point (for a URDF link driven by a joint, the frame of that
joint); every vector below is in ``F_a`` coordinates unless it says *world*.

* ``V_a = [v; w]`` the body twist of ``F_a`` (Pinocchio ``LOCAL``, linear first).
* ``p`` the constrained point, so its velocity is ``v_c = v + w x p = v - hat(p) w``.
* ``C`` (k x 3, orthonormal rows) the directions along which the point may not move.

An equality constraint asks ``C v_c = b`` with ``b = -K e + feed_forward``, ``e`` the
position error in metres along ``C`` (drift feedback, docs/design.md section 3). An inequality
(a barrier) asks ``C v_c >= b``.
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache
from typing import ClassVar, Literal, Protocol

import numpy as np
import pinocchio as pin

from .gain_rule import GainRule
from .kinematics import frame_placement, resolve_frame
from .limits import MAX_CONSTRAINT_GAIN, MAX_POSITION_M, MAX_SPEED_M_S
from .norms import norm
from .registry import constraint_type
from .revision import ReadOnlyFields
from .validation import as_number, as_unit_vector, as_vector, short_repr

#: Default drift-feedback gain (1/s). Stable at a control period dt when 0 < K dt < 2;
#: 100 1/s at the default 1 kHz gives K dt = 0.1, a 10 ms error time constant.
DEFAULT_GAIN = 100.0

Parametrisation = Literal["nullspace", "paper"]

class RobotLike(Protocol):
    """What a constraint needs from a robot (``teleop.Robot`` satisfies it); read only."""

    @property
    def model(self) -> pin.Model: ...
    @property
    def constrained_link(self) -> str | None: ...
    @property
    def link_axis(self) -> np.ndarray: ...
    @property
    def link_axes(self) -> Mapping[str, np.ndarray]: ...


def link_axis_of(robot: RobotLike, link: str) -> np.ndarray:
    """The long axis of ``link`` in its own coordinates: the robot's axis for that
    constrained link (a robot with several, one per arm), else its ``link_axis``."""
    axes = getattr(robot, "link_axes", None) or {}
    return as_unit_vector(axes[link] if link in axes else robot.link_axis, "link_axis")


@dataclass(frozen=True)
class ConstraintPoint:
    """One evaluation of a constraint at a configuration, all in ``F_a`` coordinates.

    Attributes
    ----------
    p : (3,) constrained point in ``F_a``.
    C : (k, 3) orthonormal rows: the constrained directions.
    C_perp : (3 - k, 3) orthonormal rows completing ``C`` to a basis (free directions).
    error : (k,) position error along ``C`` in metres (signed distance for a plane).
    rhs : (k,) required ``C v_c``: ``-K e`` plus the feed-forward of moving geometry
        (equality); the lower bound of ``C v_c`` (barrier).
    """

    p: np.ndarray
    C: np.ndarray
    C_perp: np.ndarray
    error: np.ndarray
    rhs: np.ndarray


# ----------------------------------------------------------------------------- helpers


@cache
def constructor_fields(constraint_type: type) -> dict[str, inspect.Parameter]:
    """The named arguments of a constraint type's constructor: its :meth:`Constraint.to_dict`
    fields, in order."""
    return {name: parameter
            for name, parameter in inspect.signature(constraint_type).parameters.items()
            if parameter.kind in (parameter.POSITIONAL_OR_KEYWORD, parameter.KEYWORD_ONLY)}


def orthonormal_complement(rows: np.ndarray) -> np.ndarray:
    """Rows spanning the orthogonal complement in R^3 of the (orthonormal) ``rows``."""
    k = rows.shape[0]
    if k == 3:
        return np.zeros((0, 3))
    _, _, vt = np.linalg.svd(np.vstack([rows, np.zeros((3 - k, 3))]))
    return vt[k:].copy()


def perpendicular_basis(axis: np.ndarray) -> np.ndarray:
    """Two orthonormal rows perpendicular to the unit ``axis`` (right-handed with it)."""
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    first = cross(axis, helper)
    first /= np.linalg.norm(first)
    second = cross(axis, first)
    return np.vstack([first, second])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` of two 3-vectors: ``np.cross``'s arithmetic, bit for bit, without its
    per-call overhead (a plane calls it twice a step)."""
    a0, a1, a2 = a.tolist()
    b0, b1, b2 = b.tolist()
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def default_link(robot: RobotLike, link: str | None) -> str:
    """``link`` or the robot's constrained link; raise if neither is known."""
    if link is not None:
        return link
    if robot.constrained_link is None:
        raise ValueError(
            "this robot has no constrained_link: pass link=... or load the robot "
            "with constrained_link=..."
        )
    return robot.constrained_link


def link_point_at(robot: RobotLike, q: np.ndarray, link: str | None, link_point=None,
                  distance: float | None = None) -> tuple[str, np.ndarray, pin.SE3]:
    """Resolve a link point given as ``link_point`` (link coordinates) or ``distance`` m
    along the robot's link axis: returns ``(link, point in link coordinates, link placement
    at q)``."""
    link = default_link(robot, link)
    if (link_point is None) == (distance is None):
        raise ValueError("give exactly one of link_point or distance")
    if link_point is None:
        link_point = as_number(distance, "distance") * link_axis_of(robot, link)
    link_point = as_vector(link_point, 3, "link_point")
    return link, link_point, frame_placement(robot.model, q, link)


def structure_nullspace(p: np.ndarray, C: np.ndarray, C_perp: np.ndarray | None = None) -> np.ndarray:
    """Singularity-free structure matrix ``S`` (6 x (6-k)) of docs/design.md section 3.

    ``V_a = S [u; w]`` with ``v = C_perp^T u + C^T C hat(p) w``: the point ``p`` then
    moves with ``C v_c = C C^T C hat(p) w - C hat(p) w = 0`` for every ``u, w``. The
    columns span exactly ``null(C [I, -hat(p)])`` and stay well conditioned when ``p``
    approaches the origin of ``F_a`` (where the paper's ``1/a`` form, eqs 9 and 11-13,
    is singular).
    """
    k = C.shape[0]
    S = np.zeros((6, 6 - k))
    S[:3, : 3 - k] = (orthonormal_complement(C) if C_perp is None else C_perp).T
    S[:3, 3 - k :] = C.T @ (C @ pin.skew(p))
    S[3:, 3 - k :] = np.eye(3)
    return S


def structure_paper(p: np.ndarray, C: np.ndarray) -> np.ndarray:
    """The paper's structure matrix (eqs 9-10 plane, 11-13 hole), for any axis.

    With ``p = a e`` (``a = |p|``) and constrained directions ``c_i`` perpendicular to
    ``e``, the paper pairs each constrained linear velocity ``v_i`` with the angular
    velocity ``(v_i / a) (c_i x e)`` that cancels it at the point. For the hole with
    ``e = z`` this is eq 13: ``V_a = [v1, v2, v_z, v2/a, -v1/a, w_z]``. The remaining
    columns are the free linear directions ``C_perp`` and the angular directions
    orthogonal to every ``c_i x e``. Undefined at ``a = 0`` and when ``C p != 0``.
    """
    a = float(np.linalg.norm(p))
    k = C.shape[0]
    if a < 1e-9:
        raise ValueError(
            "the paper's parametrisation is singular at a = 0 (constrained point at the "
            "origin of F_a): use parametrisation='nullspace'"
        )
    e = p / a
    if k > 2 or np.max(np.abs(C @ e)) > 1e-9:
        raise ValueError(
            "the paper's parametrisation needs at most 2 constrained directions, all "
            "perpendicular to the point's position p; use parametrisation='nullspace'"
        )
    D = np.cross(C, e)  # rows c_i x e, orthonormal since c_i ⟂ e
    S = np.zeros((6, 6 - k))
    S[:3, :k] = C.T
    S[3:, :k] = D.T / a
    S[:3, k:3] = orthonormal_complement(C).T
    S[3:, 3:] = orthonormal_complement(D).T
    return S


def structure_of(state: ConstraintPoint, parametrisation: Parametrisation = "nullspace") -> np.ndarray:
    """Structure matrix ``S`` of an evaluated constraint in the chosen parametrisation."""
    if parametrisation == "nullspace":
        return structure_nullspace(state.p, state.C, state.C_perp)
    if parametrisation == "paper":
        return structure_paper(state.p, state.C)
    raise ValueError(f"unknown parametrisation {parametrisation!r}: 'nullspace' or 'paper'")


# ----------------------------------------------------------------------------- base


class Constraint(ReadOnlyFields, ABC):
    """A constraint on one point of one link of the chain.

    Subclasses say where the point is and which directions are constrained; this base
    class turns that into the structure matrix ``S`` (for the analytical CJM) and the
    joint-space rows ``A qd = b`` (for the general CJM and the QP).

    A constraint also describes itself: its ``kind`` name and ``label``, :meth:`to_dict` /
    :meth:`from_dict` (the constructor's arguments; the kinds are listed in
    :mod:`constraints.registry`), and the world reference point of its geometry
    (:attr:`position`, moved by :meth:`move_to`). A new type sets the class attributes
    below and is registered (:func:`constraints.registry.register`). What the other
    layers do with a type is a piece each registers by type, looked up along the type's
    bases (no layer branches on a type): the page's drawing
    (``web/constraint_drawing.py``) and placement (``web/constraint_placement.py``), a
    physics plant's wall (``teleop/plants/walls.py``), a port the collision avoidance
    leaves alone (:mod:`constraints.collision.ports`), sliding along its link
    (``teleop/experiments/sliding.py``), the analytical CJM's affine form
    (``controllers/cjm/affine_forms.py``) and the compiled CJM step's form
    (``controllers/cjm/compiled_forms.py``). Its fields are read-only and change by
    assignment only, each assignment replacing its ``revision``
    (:mod:`constraints.revision`): how the compiled readers see a change.

    Parameters
    ----------
    link : name of the link (frame) carrying the constrained point.
    gain : drift-feedback gain ``K`` in 1/s (``C v_c = -K e``).
    """

    #: number of constrained directions k
    dim: int
    #: True for ``C v_c = b``, False for the one-sided ``C v_c >= b`` (barrier)
    is_equality: bool = True
    #: whether the paper's ``1/a`` structure matrix (eqs 9-13) exists wherever ``a != 0``:
    #: only when ``C`` stays perpendicular to ``p`` (a hole)
    has_paper_form: bool = False
    #: the type's name in dicts and session files ("hole", "plane", ...)
    kind: ClassVar[str]
    #: the attribute holding the geometry's world reference point (:attr:`position`)
    position_attribute: ClassVar[str]
    #: the constructor fields holding world directions (velocities, normals), which
    #: :meth:`moved` rotates; the world point it moves is :attr:`position`
    world_directions: ClassVar[tuple[str, ...]] = ("velocity",)
    #: constructor fields :meth:`to_dict` leaves out while they hold their defaults
    omitted_at_default: ClassVar[tuple[str, ...]] = ()
    #: what the operator reads of the type ("point lock"): names and messages
    label: ClassVar[str] = "constraint"
    #: world velocity (m/s) of the reference point, fed forward (set by :meth:`move_to`)
    velocity: np.ndarray

    def __init__(self, link: str, gain: float = DEFAULT_GAIN) -> None:
        if not isinstance(link, str) or not link:
            raise ValueError(f"link must be a non-empty link name, got {short_repr(link)}")
        self.link = link
        #: the control period (s) a controller last accepted this constraint at
        #: (:meth:`check_gain`), or None before any did
        self._checked_period: float | None = None
        self.gain = gain

    #: the gains stable at a period: drift feedback ``e+ = (1 - K dt) e`` converges for
    #: ``0 <= K dt < 2`` (docs/design.md section 3)
    gain_rule: ClassVar[GainRule] = GainRule(max_gain_period=2.0)

    @property
    def gain(self) -> float:
        """Drift-feedback gain ``K`` (1/s), a finite number >= 0 (0: no drift feedback).

        Setting it goes through the checks of construction (a non-number, a negative or
        non-finite gain) and, once a controller has taken this constraint
        (:meth:`check_gain`), through that controller's stability test at its period:
        each raises ``ValueError`` and leaves the gain as it was (docs/design.md
        section 3.4).
        """
        return self._gain

    @gain.setter
    def gain(self, value: float) -> None:
        gain = as_number(value, "gain", 0.0, maximum=MAX_CONSTRAINT_GAIN)
        if self._checked_period is not None:
            problem = self.gain_rule.instability(type(self).__name__, gain,
                                                 self._checked_period)
            if problem is not None:
                raise ValueError(problem)
        self._gain = gain

    def check_gain(self, dt: float) -> None:
        """Refuse a gain that is unstable at control period ``dt`` (``ValueError``);
        a controller calls it when it takes the constraint, and the gain setter checks
        against the last ``dt`` accepted here."""
        problem = self.gain_rule.instability(type(self).__name__, self._gain, dt)
        if problem is not None:
            raise ValueError(problem)
        self._checked_period = dt

    # -- geometry, in F_a coordinates, given the link's world placement --------------

    @abstractmethod
    def point(self, placement: pin.SE3) -> np.ndarray:
        """The constrained point ``p`` (3,) in link coordinates."""

    @abstractmethod
    def directions(self, placement: pin.SE3) -> np.ndarray:
        """The constrained directions ``C`` (k x 3, orthonormal rows) in link coordinates."""

    @abstractmethod
    def error(self, placement: pin.SE3) -> np.ndarray:
        """Position error (k,) in metres along ``C``."""

    def free_directions(self, placement: pin.SE3) -> np.ndarray:
        """Rows ``C_perp`` (3-k x 3) completing ``C``; subclasses override with closed forms."""
        return orthonormal_complement(self.directions(placement))

    def feed_forward(self, placement: pin.SE3) -> np.ndarray:
        """``C v`` for the velocity of the constraint's own geometry (moving hole/plane)."""
        return np.zeros(self.dim)

    def evaluate(self, placement: pin.SE3) -> ConstraintPoint:
        """Everything a controller needs at one configuration, computed once."""
        e = self.error(placement)
        return ConstraintPoint(
            p=self.point(placement),
            C=self.directions(placement),
            C_perp=self.free_directions(placement),
            error=e,
            rhs=self.feed_forward(placement) - self.gain * e,
        )

    def point_world(self, placement: pin.SE3) -> np.ndarray:
        """The constrained point in the world frame (m)."""
        return placement.act(self.point(placement))

    # -- the geometry's world reference point ----------------------------------------------

    @property
    def position(self) -> np.ndarray:
        """World reference point of the geometry (m): hole centre, plane point, lock
        target (a copy: move it with :meth:`move_to`)."""
        return getattr(self, self.position_attribute).copy()

    def move_to(self, position=None, velocity=(0.0, 0.0, 0.0), **named) -> None:
        """Move the geometry's world reference point (m) and set its velocity (m/s).

        The velocity is fed forward: ``rhs`` gains ``C v`` (``v`` in ``F_a``
        coordinates). The subclasses' own names of the point work as keywords too:
        ``hole.move_to(center=...)``, ``plane.move_to(plane_point=...)``,
        ``lock.move_to(target=...)``.
        """
        if named:
            unexpected = sorted(set(named) - {self.position_attribute})
            if unexpected or position is not None:
                raise TypeError(
                    f"{type(self).__name__}.move_to() takes the point as position or "
                    f"{self.position_attribute}, once; got {sorted(named)}")
            position = named[self.position_attribute]
        position = as_vector(position, 3, self.position_attribute, MAX_POSITION_M)
        velocity = as_vector(velocity, 3, f"{self.kind} velocity", MAX_SPEED_M_S)
        setattr(self, self.position_attribute, position)
        self.velocity = velocity

    def moved(self, motion: pin.SE3) -> "Constraint":
        """A copy whose world geometry the rigid ``motion`` ``G`` carries: the reference
        point ``x -> G x``, each of :attr:`world_directions` ``d -> R_G d``; link
        coordinates and gains as they are. At the link placement ``G T_a`` the copy's
        error is this one's at ``T_a``, so ``G = T_true T_model^-1`` puts the geometry
        where the real link met it (docs/design.md section 15.1, "Calibration error")."""
        data = self.to_dict()
        data[self.position_attribute] = motion.act(self.position).tolist()
        for name in self.world_directions:
            if name in data:
                data[name] = (motion.rotation @ np.asarray(data[name], dtype=float)).tolist()
        return type(self).from_dict(data)

    def violation(self, placement: pin.SE3) -> float:
        """How far (m) the point is from satisfying the constraint (0 when it does):
        ``|error|`` (:func:`constraints.norms.norm`: the loop's measures of many periods at
        once round it the same, whatever BLAS kernel the CPU selects)."""
        return norm(self.error(placement))

    # -- description: to and from a JSON-ready dict ----------------------------------------

    def to_dict(self) -> dict:
        """``kind`` and the constructor's arguments, JSON-ready (world frame, m, 1/s).

        ``Constraint.from_dict(c.to_dict())`` rebuilds ``c``. Each constructor argument is
        an attribute of the same name; ``velocity`` is left out while the geometry is at
        rest (as in session files written before it was recorded), and the fields of
        :attr:`omitted_at_default` while they hold their defaults.
        """
        data = {"kind": self.kind}
        fields = constructor_fields(type(self))
        for name in fields:
            value = getattr(self, name)
            if name == "velocity" and not np.any(value):
                continue
            if name in self.omitted_at_default and value == fields[name].default:
                continue
            data[name] = value.tolist() if isinstance(value, (np.ndarray, np.generic)) else value
        return data

    @classmethod
    def from_dict(cls, data: Mapping) -> "Constraint":
        """Build a constraint from :meth:`to_dict` output (the ``kind`` picks the type).

        Bad input raises ``ValueError`` naming the field: an unknown or missing ``kind``,
        an unknown or missing field, or a bad value.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"a constraint must be an object with a 'kind', got {short_repr(data)}")
        kind_type = constraint_type(data.get("kind"))
        kind = kind_type.kind
        if not issubclass(kind_type, cls):
            raise ValueError(f"kind {kind!r} is not a {cls.__name__}")
        fields = constructor_fields(kind_type)
        given = {name: value for name, value in data.items() if name != "kind"}
        for name in given:
            if name not in fields:
                raise ValueError(f"unknown field {name!r} for a {kind} "
                                 f"(its fields: {', '.join(fields)})")
        missing = [repr(name) for name, parameter in fields.items()
                   if parameter.default is inspect.Parameter.empty and name not in given]
        if missing:
            raise ValueError(f"a {kind} needs the field{'s' * (len(missing) > 1)} "
                             f"{', '.join(missing)}")
        try:
            return kind_type(**given)
        except ValueError as error:
            raise ValueError(f"bad {kind}: {error}") from error

    # -- what the controllers use ------------------------------------------------------

    def structure(
        self, placement: pin.SE3, parametrisation: Parametrisation = "nullspace"
    ) -> np.ndarray:
        """Structure matrix ``S`` (6 x (6-k)) with ``V_a = S [free variables]``."""
        return structure_of(self.evaluate(placement), parametrisation)

    def rows(
        self, model: pin.Model, data: pin.Data, frame_id: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Joint-space rows ``(A, b)``: ``A qd = b`` (or ``>= b`` for a barrier).

        ``A = C [I, -hat(p)] J_a`` with ``J_a`` the ``LOCAL`` Jacobian of the link. The
        caller must have run ``pin.computeJointJacobians`` and
        ``pin.updateFramePlacements`` on ``data`` for the current ``q``.
        """
        if frame_id is None:
            frame_id = resolve_frame(model, self.link)
        rows, state, _ = evaluated_rows(self, model, data, frame_id)
        return rows, state.rhs

    def __repr__(self) -> str:
        return f"{type(self).__name__}(link={self.link!r}, gain={self._gain})"


def evaluated_rows(constraint: Constraint, model: pin.Model, data: pin.Data,
                   frame_id: int) -> tuple[np.ndarray, ConstraintPoint, pin.SE3]:
    """:meth:`Constraint.rows`' ``A = C [I, -hat(p)] J_a`` with the evaluation it comes
    from (error, point, right-hand side) and the link's placement, for a caller that reads
    them too (the loop's measures) without evaluating the constraint again."""
    placement = pin.updateFramePlacement(model, data, frame_id)  # cheaper than data.oMf[i]
    state = constraint.evaluate(placement)
    jacobian = pin.getFrameJacobian(model, data, frame_id, pin.LOCAL)
    point_jacobian = jacobian[:3] - pin.skew(state.p) @ jacobian[3:]
    return state.C @ point_jacobian, state, placement
