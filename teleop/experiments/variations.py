"""Random trocar placements and operator paths, drawn from a seeded distribution
(docs/design.md section 15.1.1).

A :class:`Variation` turns any :class:`~teleop.experiments.plan.Plan` (a scenario or a
recorded session) into another one of the same family: every constraint slid along its link
by a uniform draw (the constraint still holds where it is placed), and every EE target moved
by a smooth random path that starts at rest. Both off by default: the plan is unchanged.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pinocchio as pin

from constraints import Constraint
from constraints.validation import as_number
from teleop.limits import MAX_PATH_AMPLITUDE_M, MAX_TROCAR_SHIFT_M
from teleop.loop import Targets
from teleop.loop.targets import target_poses
from teleop.robots import Robot
from teleop.seeds import stream

from .plan import Plan, smoothstep
from .sliding import slid_along_link, sliding_axis

#: The draws' streams of the seed (:func:`teleop.seeds.stream`): the encoder noise draws
#: from ``default_rng(seed)``, so the three streams are independent.
TROCAR_STREAM, PATH_STREAM = 0x7120CA, 0x9A7B

#: Sinusoids per EE path, the range (Hz) their frequencies are drawn from, and the fade-in (s).
PATH_TERMS = 3
PATH_FREQUENCY_RANGE_HZ = (0.05, 0.5)
PATH_RAMP_S = 1.0


@dataclass(frozen=True)
class OperatorPath:
    """One EE's random motion (world frame, m), translation only:
    ``x(t) = s(t / T) sum_k a u_k sin(2 pi f_k t + phi_k)``, ``s`` the quintic
    :func:`smoothstep` over ``T =`` :data:`PATH_RAMP_S`, so ``x(0) = 0`` and ``x'(0) = 0``,
    and ``|x(t)| <= K a`` for ``K`` terms.

    Attributes
    ----------
    directions : (K, 3) unit rows ``u_k``.
    frequencies : (K,) ``f_k`` (Hz).
    phases : (K,) ``phi_k`` (rad).
    term_amplitude : ``a`` (m).
    """

    directions: np.ndarray
    frequencies: np.ndarray
    phases: np.ndarray
    term_amplitude: float

    def __call__(self, t: float) -> np.ndarray:
        """``x(t)`` (3,) in metres."""
        waves = np.sin(2.0 * math.pi * self.frequencies * t + self.phases)
        return smoothstep(t / PATH_RAMP_S) * self.term_amplitude * (waves @ self.directions)


class SlidConstraints:
    """One run's slid constraints (docs/design.md 15.1.1): each constraint the plan makes
    or its ``update`` adds gets a copy slid along its link by the next draw
    ``U(-shift, shift)`` from ``rng``, at the configuration where it appears; the plan keeps
    moving its own objects and each copy follows its original's moves, displaced by the
    same world vector ``d = offset a``."""

    def __init__(self, robot: Robot, shift: float, rng: np.random.Generator) -> None:
        self.robot, self.shift, self.rng = robot, shift, rng
        #: id of each original -> (the original, its slid copy, the world shift d)
        self._copies: dict[int, tuple[Constraint, Constraint, np.ndarray]] = {}
        #: id of each copy -> its original
        self._originals: dict[int, Constraint] = {}

    def slid(self, originals: list[Constraint], q: np.ndarray) -> list[Constraint]:
        """The copies of ``originals``, sliding those not seen before at ``q``."""
        copies = []
        for original in originals:
            if id(original) not in self._copies:
                offset = float(self.rng.uniform(-self.shift, self.shift))
                copy = slid_along_link(original, self.robot, q, offset)
                axis = sliding_axis(original, self.robot, q)
                shift = np.zeros(3) if axis is None else offset * axis
                self._copies[id(original)] = (original, copy, shift)
                self._originals[id(copy)] = original
            copies.append(self._copies[id(original)][1])
        return copies

    def originals(self, constraints: list[Constraint]) -> list[Constraint]:
        """The plan's own objects behind the copies ``constraints``."""
        return [self._originals.get(id(constraint), constraint) for constraint in constraints]

    def follow(self) -> None:
        """Each copy at its original's reference point plus ``d``, with its velocity."""
        for original, copy, shift in self._copies.values():
            position = original.position + shift
            if copy is not original and not (np.array_equal(copy.position, position)
                                             and np.array_equal(copy.velocity, original.velocity)):
                copy.move_to(position, velocity=original.velocity)


@dataclass(frozen=True)
class Variation:
    """How far a plan's trocars and operator paths vary, and the seed of the draws.

    Attributes
    ----------
    trocar_shift : each constraint slides along its link by ``U(-trocar_shift,
        trocar_shift)`` m; 0: in place.
    path_amplitude : each EE target moves by a smooth random path of at most this many m;
        0: as scripted.
    seed : seed of the draws (the same ``--seed`` as the encoder noise, another stream).
    """

    trocar_shift: float = 0.0
    path_amplitude: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        """Each field in its range, at most the maxima of :mod:`teleop.limits`
        (``ValueError`` naming it)."""
        object.__setattr__(self, "trocar_shift", as_number(
            self.trocar_shift, "trocar_shift", 0.0, maximum=MAX_TROCAR_SHIFT_M))
        object.__setattr__(self, "path_amplitude", as_number(
            self.path_amplitude, "path_amplitude", 0.0, maximum=MAX_PATH_AMPLITUDE_M))
        if isinstance(self.seed, (bool, np.bool_)) or not isinstance(self.seed, (int, np.integer)) \
                or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")
        object.__setattr__(self, "seed", int(self.seed))

    @property
    def none(self) -> bool:
        """Neither trocars nor paths vary: :meth:`apply` leaves the plan as it is."""
        return self.trocar_shift == 0.0 and self.path_amplitude == 0.0

    @property
    def active(self) -> bool:
        """Trocars or paths vary."""
        return not self.none

    def to_dict(self) -> dict[str, float | int]:
        """The ``variation`` entry of metrics.json (units in the key names)."""
        return {"trocar_shift_m": self.trocar_shift, "path_amplitude_m": self.path_amplitude,
                "seed": self.seed}

    def describe(self) -> str:
        """One line for humans: ``no random variation`` or what varies."""
        if self.none:
            return "no random variation"
        parts = []
        if self.trocar_shift:
            parts.append(f"trocars slid up to {1e3 * self.trocar_shift:g} mm along their links")
        if self.path_amplitude:
            parts.append(f"operator paths within {1e3 * self.path_amplitude:g} mm")
        return ", ".join(parts) + f" (seed {self.seed})"

    def trocar_rng(self) -> np.random.Generator:
        """A fresh generator of the trocar offsets: the same draws at every call."""
        return stream(self.seed, TROCAR_STREAM)

    def operator_paths(self, count: int) -> list[OperatorPath]:
        """One :class:`OperatorPath` per EE, each term of amplitude ``path_amplitude /``
        :data:`PATH_TERMS`: per EE, unit directions (normalised Gaussian vectors),
        frequencies ``U(`` :data:`PATH_FREQUENCY_RANGE_HZ` ``)``, phases ``U(0, 2 pi)``."""
        rng = stream(self.seed, PATH_STREAM)
        paths = []
        for _ in range(count):
            directions = rng.standard_normal((PATH_TERMS, 3))
            directions /= np.linalg.norm(directions, axis=1, keepdims=True)
            paths.append(OperatorPath(directions, rng.uniform(*PATH_FREQUENCY_RANGE_HZ, PATH_TERMS),
                                      rng.uniform(0.0, 2.0 * math.pi, PATH_TERMS),
                                      self.path_amplitude / PATH_TERMS))
        return paths

    def apply(self, plan: Plan) -> Plan:
        """A new plan (``dataclasses.replace``) with this variation (docs/design.md 15.1.1).

        With ``trocar_shift``, ``make_constraints`` returns its constraints slid along their
        links (:class:`SlidConstraints`, a fresh one per call: the same draws every run);
        ``update`` moves the plan's own objects, which the slid copies follow, and those it
        adds are slid at the configuration it is given. As for a session, ``update``
        serves the run of the latest ``make_constraints`` call. With ``path_amplitude``,
        each EE target's translation gains its :class:`OperatorPath`.
        """
        changes: dict[str, Any] = {}
        if self.trocar_shift:
            make, update = plan.make_constraints, plan.update
            runs: list[SlidConstraints] = []

            def make_constraints() -> list[Constraint]:
                runs[:] = [SlidConstraints(plan.robot, self.trocar_shift, self.trocar_rng())]
                return runs[0].slid(make(), plan.q0)

            def slid_update(t: float, constraints: list[Constraint],
                            q: np.ndarray) -> list[Constraint] | None:
                run = runs[0]
                changed = update(t, run.originals(constraints), q)
                copies = None if changed is None else run.slid(changed, q)
                run.follow()
                return copies

            changes.update(make_constraints=make_constraints, update=slid_update)
        if self.path_amplitude:
            target, paths = plan.target, self.operator_paths(len(plan.robot.ee_frames))

            def moved_target(t: float) -> Targets:
                scripted = target(t)
                poses = [pin.SE3(pose.rotation, pose.translation + path(t))
                         for pose, path in zip(target_poses(scripted), paths)]
                return poses[0] if isinstance(scripted, pin.SE3) else poses

            changes["target"] = moved_target
        return replace(plan, **changes)
