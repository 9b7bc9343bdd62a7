"""``teleop`` subcommands that live in a layer above this one, registered, not imported.

A distribution registers a subcommand under the entry-point group :data:`COMMAND_GROUP`:
the entry point's name is the subcommand's, its object a :class:`Command`. This package
ships ``web = "web.cli:COMMAND"`` (pyproject.toml), so ``teleop web`` runs the browser UI
while ``teleop`` never imports ``web`` (the layers, docs/design.md). Entry points are read
from the installed metadata (``pip install -e .`` writes it), and loaded only to run one of
them or to list them (``teleop --help``). A registered command that
cannot be loaded (its module or a dependency missing) leaves the other commands working:
``teleop --help`` says it cannot be loaded and running it prints why, one line, exit code 2.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from importlib import metadata
from collections.abc import Set
from typing import Callable

from .arguments import ArgumentParser, HelpFormatter, one_line, sentence

#: The entry-point group holding the registered subcommands.
COMMAND_GROUP = "teleop.commands"


@dataclass(frozen=True)
class Command:
    """A subcommand as it describes itself: its one-line ``summary`` (``teleop --help``; its
    description, capitalised), its options (``add_arguments`` adds them to a parser), what
    it does (``run(args, prog)`` -> exit code; ``prog`` names it in messages, e.g.
    ``teleop web``) and an ``epilog`` for its help."""

    summary: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace, str], int]
    epilog: str = field(default="")

    def parser(self, prog: str) -> ArgumentParser:
        """A parser of its own, for running it without ``teleop`` (``python -m web``)."""
        parser = ArgumentParser(prog=prog, description=sentence(self.summary), epilog=self.epilog,
                                formatter_class=HelpFormatter)
        self.add_arguments(parser)
        return parser


@dataclass(frozen=True)
class Registered:
    """One entry of :data:`COMMAND_GROUP`: the loaded command, or why it could not be loaded."""

    name: str
    command: Command | None
    unavailable: str | None = None


def _load(entry_point: metadata.EntryPoint) -> Registered:
    try:
        command = entry_point.load()
    except Exception as error:  # any failure of the command's own import: that command only
        return Registered(entry_point.name, None, f"cannot be loaded from {entry_point.value} "
                                                  f"({type(error).__name__}: {one_line(error)})")
    if not isinstance(command, Command):
        return Registered(entry_point.name, None, f"cannot be loaded from {entry_point.value} "
                                                  f"(a {type(command).__name__}, not a Command "
                                                  f"of {Command.__module__})")
    return Registered(entry_point.name, command)


def registered_commands(taken: Set[str] = frozenset()) -> list[Registered]:
    """The commands of :data:`COMMAND_GROUP`, by name, loaded; a name in ``taken`` (a
    built-in command's, which keeps it) is left out."""
    found = []
    for entry_point in sorted(metadata.entry_points(group=COMMAND_GROUP), key=lambda e: e.name):
        if entry_point.name in taken:
            continue
        found.append(_load(entry_point))
    return found
