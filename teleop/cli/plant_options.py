"""The plant's options on a command line (docs/cli.md), generated from their one
declaration (:data:`teleop.plants.options.PLANT_OPTIONS`): ``--plant`` and the options of
each plant a command takes (``kinematic``, ``mujoco`` with its physics settings or ``ros2``
with its topics, docs/ros2.md, and the abdominal wall's stiffness); shared by compare,
replay, record, bench, sim and ``teleop web``."""

from __future__ import annotations

import argparse
from typing import Any

from teleop.plants.choice import PlantChoice
from teleop.plants.options import PLANT, PLANT_OPTIONS, PlantOption
from teleop.plants.ros2.settings import Ros2Settings
from teleop.plants.settings import PlantSettings

#: A fresh holder of each kind: the defaults the options' help shows.
_DEFAULTS: dict[str, Any] = {"plant": PlantChoice(), "physics": PlantSettings(),
                             "ros2": Ros2Settings()}


def _left_out(option: PlantOption) -> str:
    """The plants that take ``option`` and what leaving it out means: the field's default
    (in the option's unit), or the declared words."""
    if option.left_out:
        words = option.left_out
    else:
        default = getattr(_DEFAULTS[option.holder], option.field)
        words = f"{default / option.scale:g}" if isinstance(default, float) else str(default)
    return f"({', '.join(option.plants)}) (default: {words})"


def add_plant_options(group: argparse._ActionsContainer, command: str,
                      plant_help: str | None = None) -> None:
    """The plant options ``command`` takes (each declaration's ``commands``), on ``group``:
    ``--plant`` (``plant_help``: what leaving it out means, None: no ``--plant``, the
    command chooses its plant otherwise) and each plant's own, left out: None."""
    if plant_help is not None and command in PLANT.commands:
        PLANT.add_to(group, left_out=plant_help)
    for option in PLANT_OPTIONS:
        if command in option.option.commands:
            shared = option.option
            group.add_argument(shared.option, dest=shared.name, metavar=shared.metavar,
                               help=f"{shared.help_text()} {_left_out(option)}",
                               **shared.range.argparse_keywords())


def add_plant_group(parser: argparse.ArgumentParser, command: str, base: str) -> None:
    """A group of its own with ``--plant`` and the options ``command`` takes; ``base`` says
    what an option left out means."""
    group = parser.add_argument_group(
        "the plant", "the robot the loop drives, the same for every controller "
        "(docs/design.md section 17); an option left out: " + base)
    add_plant_options(group, command, "kinematic")


def given_plant_options(args: argparse.Namespace) -> dict[str, Any]:
    """The plant options given on the command line, by name (their values parsed)."""
    return {option.name: getattr(args, option.name) for option in PLANT_OPTIONS
            if getattr(args, option.name, None) is not None}


def plant_choice(args: argparse.Namespace, base: PlantChoice | None = None) -> PlantChoice:
    """The plant the options ask for, over ``base`` (a session's; None: the kinematic
    plant): :meth:`PlantChoice.with_options` (``ValueError`` naming an option the plant
    does not take)."""
    return PlantChoice.with_options(given_plant_options(args), getattr(args, "plant", None),
                                    base)
