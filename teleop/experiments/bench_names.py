"""The names of ``teleop bench``'s problems (light: the command line's defaults and help
read them without loading the bench)."""

from __future__ import annotations

from typing import Sequence

from teleop.robots import BUILTIN_ROBOTS

SCALING_DOFS = (8, 16, 32, 64)
SCALING_HOLES = (1, 2, 4, 8)
#: the problems of one constraint of each other type on sda10f (bench.bench_constraints)
CONSTRAINT_PROBLEMS = ("sda10f/plane", "sda10f/lock", "sda10f/barrier")
#: what ``teleop bench`` runs by default: every built-in robot, the constraint problems
#: after sda10f's hole
DEFAULT_PROBLEMS = tuple(name for robot in BUILTIN_ROBOTS for name in
                         (robot, *(p for p in CONSTRAINT_PROBLEMS if p.startswith(f"{robot}/"))))


def scaling_problems(dofs: Sequence[int] = SCALING_DOFS,
                     holes: Sequence[int] = SCALING_HOLES) -> tuple[str, ...]:
    """The scaling runs' problems: one hole on each chain, then holes on the 32-DoF one."""
    return (*(f"chain{dof}" for dof in dofs), *(f"chain32/{count}holes" for count in holes))


def known_problems() -> tuple[str, ...]:
    """Every name the bench takes: the built-in robots, the constraint problems and the
    scaling runs' chains."""
    return (*BUILTIN_ROBOTS, *CONSTRAINT_PROBLEMS, *scaling_problems())


def problem_labels(name: str) -> tuple[str, ...]:
    """The timed problems of a name: the dual robot's arms close together too, without
    and with collision avoidance (``sda10f_dual/close``, ``sda10f_dual/collisions``: every
    self-collision pair, a few within the detection distance, bench.close_arms)."""
    return (name, f"{name}/close", f"{name}/collisions") if name == "sda10f_dual" else (name,)
