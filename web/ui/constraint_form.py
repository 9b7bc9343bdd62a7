"""A constraint type's form in the Constraints tab, built from its registered declaration
(docs/design.md section 5.5): an input per field of its placement
(:mod:`web.constraint_placement`), those that do not apply on the chosen link hidden. No
kind is named here: a new constraint type appears in the tab by registering its placement."""

from __future__ import annotations

from typing import Any

import numpy as np
import viser

from constraints import Constraint
from teleop.robots import Robot

from ..app.placing import field_applies, link_choices
from ..constraint_placement import placement_of
from ..placement_fields import PlacementField
from .placed_panel import NONE


class ConstraintForm:
    """The inputs of ``kind_type``'s placement fields on ``robot`` (a
    :class:`web.ui.placed_panel.KindForm`), labelled "<type label> <field label>"; the
    type has a registered placement (:func:`web.constraint_placement.placement_of`)."""

    expanded: bool = True
    hint: str | None = None

    def __init__(self, kind_type: type[Constraint], robot: Robot) -> None:
        self.type = kind_type
        self.robot = robot
        self.label = self.folder = kind_type.label
        self.inputs: dict[str, viser.GuiInputHandle[Any]] = {}
        placement = placement_of(kind_type)
        if placement is None:
            raise ValueError(f"a {kind_type.label} is not placed from the UI: its type "
                             "registers no placement")
        #: the placement's fields, one input each
        self.fields = placement.fields
        links = [field for field in self.fields if field.type == "link"]
        self._link_field = links[0] if links else None

    def build(self, gui: viser.GuiApi) -> None:
        self.inputs = {field.name: self._input(gui, field) for field in self.fields}
        if self._link_field is not None:
            self.inputs[self._link_field.name].on_update(lambda _: self._show_applicable())
        self._show_applicable()

    def _input(self, gui: viser.GuiApi, field: PlacementField) -> viser.GuiInputHandle[Any]:
        """The input of one placement field."""
        label, hint = f"{self.label} {field.label}", field.hint or None
        if field.type == "link":
            choices = link_choices(self.robot, field) or (NONE,)
            return gui.add_dropdown(label, choices, initial_value=choices[0],
                                    visible=self._link_menu_shown(field, choices), hint=hint)
        if field.type in ("link_point", "direction"):
            return gui.add_vector3(label, np.asarray(field.default, dtype=float),
                                   step=field.step or 0.05, hint=hint)
        return gui.add_number(label, field.default, min=field.minimum, max=field.maximum,
                              step=field.step or 0.001, hint=hint)

    def _link_menu_shown(self, field: PlacementField, choices: tuple[str, ...]) -> bool:
        """A menu of one choice is hidden; so is a menu of any moving link on a robot with
        one arm on a fixed base (the constrained link is then the one that matters)."""
        if len(choices) < 2:
            return False
        return (field.links == "constrained" or len(self.robot.ee_frames) > 1
                or self.robot.root_joint != "fixed")

    def _chosen_link(self) -> str | None:
        """The link chosen in the link menu (None: none to choose, or no menu)."""
        if self._link_field is None:
            return None
        value = self.inputs[self._link_field.name].value
        return value if value in link_choices(self.robot, self._link_field) else None

    def _placed_on(self) -> str | None:
        """The link a new one goes on: the one chosen, else the first constrained."""
        chosen = self._chosen_link()
        return chosen if chosen is not None else next(iter(self.robot.constrained_links), None)

    def _show_applicable(self) -> None:
        """On the chosen link, show the inputs that apply (a distance on a link with an
        instrument axis, a point in link coordinates on one without)."""
        link = self._placed_on()
        for field in self.fields:
            if field.type in ("distance", "link_point"):
                self.inputs[field.name].visible = field_applies(field, self.robot, link)

    def values(self) -> dict[str, object]:
        """The inputs' values that apply on the chosen link (the link itself as chosen:
        None when there is none to choose)."""
        chosen, link = self._chosen_link(), self._placed_on()
        values: dict[str, object] = {}
        for field in self.fields:
            if field.type == "link":
                values[field.name] = chosen
            elif field_applies(field, self.robot, link):
                values[field.name] = self.inputs[field.name].value
        return values
