"""What the loop calls each equality row and each constraint in its records and plots
(docs/design.md section 15.2)."""

from __future__ import annotations

from typing import Sequence

from constraints import Constraint

#: What the velocity along a constraint's rows is called, by its number of rows k
#: (a plane: its normal; a hole: the two directions across the link; a lock: world x, y, z).
ROW_WORDS = {1: ("normal velocity at {name}",),
             2: ("lateral velocity at {name}, direction 1",
                 "lateral velocity at {name}, direction 2"),
             3: ("x velocity at {name}", "y velocity at {name}", "z velocity at {name}")}


def row_labels(constraints: Sequence[Constraint]) -> tuple[str, ...]:
    """Words for every equality row, in order: ``"lateral velocity at hole 1, direction 1
    (m/s)"``; constraints are numbered by kind in list order (docs/design.md section 15.2)."""
    labels: list[str] = []
    numbers: dict[str, int] = {}
    for constraint in constraints:
        if not constraint.is_equality:
            continue
        numbers[constraint.label] = numbers.get(constraint.label, 0) + 1
        name = f"{constraint.label} {numbers[constraint.label]}"
        labels += [f"{words.format(name=name)} (m/s)" for words in ROW_WORDS[constraint.dim]]
    return tuple(labels)


def constraint_names(constraints: Sequence[Constraint]) -> tuple[str, ...]:
    """One name per constraint, in order: ``"hole 2 (arm_right_link_5_r)"``, numbered by
    kind in list order (equalities and barriers alike) and naming the link it holds."""
    names: list[str] = []
    numbers: dict[str, int] = {}
    for constraint in constraints:
        numbers[constraint.label] = numbers.get(constraint.label, 0) + 1
        names.append(f"{constraint.label} {numbers[constraint.label]} ({constraint.link})")
    return tuple(names)
