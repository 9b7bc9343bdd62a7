"""Setting a GUI input's value from the session (a loaded scene, a linked input)."""

from __future__ import annotations

from typing import TypeVar

import viser

Value = TypeVar("Value")


def assign(handle: viser.GuiInputHandle[Value], value: Value) -> None:
    """Set ``handle``'s value (the browsers follow). viser defines the ``value`` setter
    apart from its getter, so a type checker reads the property as read-only: this is the
    one place that says otherwise."""
    handle.value = value  # type: ignore[misc]
