"""Controllers by name: the one table of known specs, and :func:`make_controller`.

A spec is ``family[:option]``:

* ``cjm``, ``cjm:general``, ``cjm:paper``, ``cjm:python`` - the Constrained Jacobian Matrix
  variants (``cjm:python``: the Python reference of the compiled step);
* ``qp:<solver>`` - the QP baseline with any installed qpsolvers backend;
* ``mink:<solver>`` - mink (MuJoCo model) with any installed qpsolvers backend.

:data:`CONTROLLER_SPECS` is the ordered table of the specs the project knows and where
each is offered by default (``teleop compare`` / ``replay``, ``teleop bench``, the bench's
scaling runs, the web UI's dropdowns); every list of controllers elsewhere reads it
through :func:`default_specs`. :func:`make_controller` builds any valid spec, in the
table or not (e.g. ``qp:clarabel`` when clarabel is installed).

Nothing heavy is imported here until a controller is built, so the CLI's help is fast.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Mapping, Set
from typing import TYPE_CHECKING, Any, Literal, Sequence

if TYPE_CHECKING:
    from constraints import Constraint
    from controllers import Controller

__all__ = ["CONTEXTS", "CONTROLLER_HELP", "CONTROLLER_SPECS", "ControllerSpec",
           "available_solvers", "default_specs", "make_controller", "spec_names"]

#: Where a spec can be offered by default: ``teleop compare`` / ``replay``, ``teleop bench``
#: on the built-in robots, the bench's generated-chain scaling runs, the web UI's dropdowns.
CONTEXTS = ("compare", "bench", "scaling", "ui")

#: The CJM variants (``cjm:<variant>``) and the CJMController keywords of each.
CJM_VARIANTS: dict[str, dict[str, Any]] = {"": {}, "analytical": {}, "general": {"form": "general"},
                "paper": {"parametrisation": "paper"}, "python": {"backend": "python"}}

#: The spec forms in one line, for help texts (no import: ``teleop --help`` stays fast).
CONTROLLER_HELP = ("cjm[:general|:paper|:python], qp:<solver>, mink:<solver> with <solver> any "
                   "installed qpsolvers backend")

#: ``make_controller(..., acceleration_limit=ROBOT)``: the robot's own acceleration limits.
ROBOT = "robot"

#: Default solver of ``qp`` and ``mink`` given without one.
DEFAULT_SOLVERS = {"qp": "proxqp", "mink": "daqp"}


@dataclass(frozen=True)
class ControllerSpec:
    """One row of the table: a spec string, a one-line description, its default uses."""

    name: str
    description: str
    offered_in: Set[str] = frozenset()  # a subset of CONTEXTS (kept as a frozenset)

    def __post_init__(self) -> None:
        object.__setattr__(self, "offered_in", frozenset(self.offered_in))
        unknown = sorted(self.offered_in - set(CONTEXTS))
        if unknown:
            raise ValueError(f"{self.name}: unknown contexts {unknown}; known: {list(CONTEXTS)}")


_ALL = frozenset(CONTEXTS)

#: The known specs, in the order every list shows them.
CONTROLLER_SPECS: tuple[ControllerSpec, ...] = (
    ControllerSpec("cjm", "CJM: analytical form for one hole/plane, general null-space form "
                   "otherwise", _ALL),
    ControllerSpec("cjm:python", "CJM, the Python reference step (the others run the compiled "
                   "step, docs/design.md section 16)", {"bench", "scaling"}),
    ControllerSpec("cjm:general", "CJM, always the general null-space form (the cross-check)",
                   {"bench", "ui"}),
    ControllerSpec("cjm:paper", "CJM, the paper's parametrisation (singular with the "
                   "constraint point at the link origin)", {"ui"}),
    ControllerSpec("qp:proxqp", "QP baseline, constraint rows as hard equalities, ProxQP", _ALL),
    ControllerSpec("qp:daqp", "QP baseline, DAQP", _ALL),
    ControllerSpec("qp:osqp", "QP baseline, OSQP", {"compare", "bench", "ui"}),
    ControllerSpec("mink:daqp", "mink (differential IK on a MuJoCo model), DAQP", _ALL),
    ControllerSpec("mink:proxqp", "mink, ProxQP", {"bench", "ui"}),
)


def spec_names() -> tuple[str, ...]:
    """Names of every spec in the table, in order."""
    return tuple(spec.name for spec in CONTROLLER_SPECS)


def default_specs(context: str) -> tuple[str, ...]:
    """Names of the specs offered by default in ``context`` (one of :data:`CONTEXTS`)."""
    if context not in CONTEXTS:
        raise ValueError(f"unknown context {context!r}; known: {list(CONTEXTS)}")
    return tuple(spec.name for spec in CONTROLLER_SPECS if context in spec.offered_in)


def available_solvers() -> list[str]:
    """The qpsolvers backends installed here (what ``qp:`` and ``mink:`` accept)."""
    import qpsolvers

    return sorted(qpsolvers.available_solvers)


def _solver(family: str, option: str) -> str:
    solver = option or DEFAULT_SOLVERS[family]
    installed = available_solvers()
    if solver not in installed:
        raise ValueError(f"QP solver {solver!r} is not available for {family}:<solver>; "
                         f"installed: {', '.join(installed)}")
    return solver


def _with_collisions(controller: Controller, collisions) -> Controller:
    """``controller`` keeping the pairs of ``collisions`` apart (None: none)."""
    if collisions is not None:
        controller.set_collisions(collisions)
    return controller


def make_controller(spec: str, robot, constraints: Sequence[Constraint] = (),
                    dt: float = 1e-3, twist_weight=None,
                    solver_settings: Mapping | None = None,
                    time_budget: float | Literal["periods"] | None = "periods",
                    acceleration_limit=None, collisions=None, jerk_limit=None) -> Controller:
    """Build a controller from its spec string; unknown specs raise ``ValueError``.
    ``twist_weight`` (the task's diagonal weight, 6 per EE or one per entry) goes to every
    family alike, as does ``acceleration_limit`` (None, the default: none, as in mink and
    pink, where limits are opt-in; ``"robot"``: the robot's own, ``robot.acceleration_limit``;
    else nv values, docs/design.md 8.4) and ``jerk_limit`` (None: none; a number for
    every joint or nv values, rad/s^3, docs/design.md 8.5; needs an acceleration limit);
    ``solver_settings`` (a mapping of the QP backend's keyword settings) and
    ``time_budget`` (a step's CPU deadline, docs/design.md 10.6) to the ``qp`` and ``mink``
    families, which have a backend. ``collisions`` (a
    ``constraints.collision.CollisionAvoidance`` on ``robot``, or None) is attached to the
    controller with its ``set_collisions`` (docs/design.md 18.6)."""
    if not isinstance(spec, str):
        raise ValueError(f"a controller spec must be a string such as 'cjm' or 'qp:daqp', "
                         f"got {spec!r}")
    from constraints.validation import as_settings

    if isinstance(acceleration_limit, str) and acceleration_limit == ROBOT:
        acceleration_limit = getattr(robot, "acceleration_limit", None)
    family, _, option = spec.strip().partition(":")
    settings = as_settings(solver_settings, "solver_settings")
    if settings and family not in ("qp", "mink"):
        raise ValueError(f"solver_settings apply to the qp and mink families, not {spec!r}")
    if family == "cjm":
        if option not in CJM_VARIANTS:
            raise ValueError(f"unknown CJM variant {option!r}: analytical, general, paper or python")
        from controllers import CJMController

        controller: Controller = CJMController(
            robot, constraints, dt=dt, twist_weight=twist_weight,
            acceleration_limit=acceleration_limit, jerk_limit=jerk_limit,
            **CJM_VARIANTS[option])
        return _with_collisions(controller, collisions)
    if family == "qp":
        from controllers import QPController

        controller = QPController(robot, constraints, solver=_solver(family, option), dt=dt,
                                  twist_weight=twist_weight, solver_settings=settings,
                                  time_budget=time_budget, acceleration_limit=acceleration_limit,
                                  jerk_limit=jerk_limit)
        return _with_collisions(controller, collisions)
    if family == "mink":
        solver = _solver(family, option)  # checked before MuJoCo (heavy) is imported
        from controllers import MinkController

        controller = MinkController(robot, constraints, solver=solver, dt=dt,
                                    twist_weight=twist_weight, solver_settings=settings,
                                    time_budget=time_budget, acceleration_limit=acceleration_limit,
                                  jerk_limit=jerk_limit)
        return _with_collisions(controller, collisions)
    raise ValueError(f"unknown controller {spec!r}: known {', '.join(spec_names())}; in general "
                     f"{CONTROLLER_HELP} ({', '.join(available_solvers())})")
