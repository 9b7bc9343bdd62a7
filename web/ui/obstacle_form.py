"""An obstacle kind's form in the Collisions tab (docs/design.md section 18): an input per
field of its constructor (:func:`web.app.collisions.obstacle_fields`), a 3-vector or a
number as its default is. No kind is named here: a new obstacle kind appears in the tab
by being registered in :data:`constraints.collision.OBSTACLE_TYPES`."""

from __future__ import annotations

from typing import Any

import numpy as np
import viser

from constraints.collision import OBSTACLE_TYPES

from ..app.collisions import obstacle_fields


class ObstacleForm:
    """The inputs of obstacle ``kind``'s constructor fields (a
    :class:`web.ui.placed_panel.KindForm`), labelled "<kind label> <field>"; one is placed
    in front of the active arm's tip."""

    expanded: bool = False
    hint: str | None = "placed in front of the active arm's tip; drag its gizmo to move it"

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.label = OBSTACLE_TYPES[kind].label
        self.folder = f"{self.label} obstacle"
        self.inputs: dict[str, viser.GuiInputHandle[Any]] = {}

    def build(self, gui: viser.GuiApi) -> None:
        self.inputs = {name: self._input(gui, name, default)
                       for name, default in obstacle_fields(self.kind).items()}

    def _input(self, gui: viser.GuiApi, name: str, default: Any) -> viser.GuiInputHandle[Any]:
        """The input of one constructor field."""
        text = f"{self.label} {name}"
        if np.ndim(default) == 1:
            return gui.add_vector3(text, np.asarray(default, dtype=float), step=0.01)
        return gui.add_number(text, float(default), min=0.0, step=0.005)

    def values(self) -> dict[str, object]:
        """Each field's value: a vector as an array, a number as a float."""
        return {name: np.asarray(widget.value, dtype=float) if np.ndim(widget.value)
                else float(widget.value) for name, widget in self.inputs.items()}
