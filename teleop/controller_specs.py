"""Controllers by name: ``cjm``, ``cjm:general``, ``cjm:paper``, ``qp:<solver>``, ``mink:<solver>``."""

from __future__ import annotations

from typing import Sequence

from constraints import Constraint
from controllers import CJMController, Controller, QPController

CONTROLLER_HELP = "cjm[:general|:paper], qp:<solver> (proxqp, daqp, osqp), mink:<solver>"


def make_controller(spec: str, robot, constraints: Sequence[Constraint] = (),
                    dt: float = 1e-3) -> Controller:
    """Build a controller from its spec string; unknown specs raise ``ValueError``."""
    name, _, option = spec.strip().partition(":")
    if name == "cjm":
        variants = {"": {}, "analytical": {}, "general": {"general_only": True},
                    "paper": {"parametrisation": "paper"}}
        if option not in variants:
            raise ValueError(f"unknown CJM variant {option!r}: analytical, general or paper")
        return CJMController(robot, constraints, **variants[option])
    if name == "qp":
        return QPController(robot, constraints, solver=option or "proxqp", dt=dt)
    if name == "mink":
        from controllers import MinkController  # MuJoCo is heavy: import on demand

        return MinkController(robot, constraints, solver=option or "daqp", dt=dt)
    raise ValueError(f"unknown controller {spec!r}: {CONTROLLER_HELP}")
