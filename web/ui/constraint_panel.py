"""The Constraints tab, built from the registry (docs/design.md section 5.5): per
registered constraint type that declares a ``placement``, a folder with an input per
field (:mod:`constraints.placement`) and an "Add <label>" button; then the placed
constraints, "Remove" and "Clear constraints". No kind is named here: a new constraint
type appears in the tab by being registered."""

from __future__ import annotations

import viser

from constraints import CONSTRAINT_TYPES, Constraint, PlacementField

from ..app import TeleopApp
from ..app.placing import field_applies, link_choices

#: what an empty menu shows
NONE = "(none)"


class ConstraintPanel:
    """The Constraints tab of :class:`web.ui.TeleopUI`. ``constraint_inputs[kind][field]``
    is the input of one field of one type."""

    server: viser.ViserServer
    app: TeleopApp
    constraint_inputs: dict[str, dict[str, object]]

    def _build_constraint_panel(self) -> None:
        gui, app = self.server.gui, self.app
        self.constraint_inputs = {}
        for kind, kind_type in CONSTRAINT_TYPES.items():
            if not kind_type.placement:
                continue
            with gui.add_folder(kind_type.label):
                inputs = {field.name: self._add_input(kind_type, field)
                          for field in kind_type.placement}
                button = gui.add_button(f"Add {kind_type.label}")
            self.constraint_inputs[kind] = inputs
            button.on_click(self._adder(kind))
            for field in kind_type.placement:
                if field.type == "link":
                    inputs[field.name].on_update(
                        lambda _, kind=kind: self._show_applicable_inputs(kind))
            self._show_applicable_inputs(kind)
        self.constraint_menu = gui.add_dropdown("placed", (NONE,))
        self.remove_button = gui.add_button("Remove")
        self.clear_button = gui.add_button("Clear constraints")
        self.remove_button.on_click(lambda event: self._guarded(
            event, lambda: app.remove_constraint(self.constraint_menu.value)))
        self.clear_button.on_click(lambda event: self._guarded(event, app.clear_constraints))

    def _add_input(self, kind_type: type[Constraint], field: PlacementField):
        """The input of one placement field, labelled "<type label> <field label>"."""
        gui, label = self.server.gui, f"{kind_type.label} {field.label}"
        if field.type == "link":
            choices = link_choices(self.app.robot, field) or (NONE,)
            return gui.add_dropdown(label, choices, initial_value=choices[0],
                                    visible=self._link_menu_shown(field, choices),
                                    hint=field.hint or None)
        if field.type in ("link_point", "direction"):
            return gui.add_vector3(label, tuple(field.default), step=field.step or 0.05,
                                   hint=field.hint or None)
        return gui.add_number(label, field.default, min=field.minimum, max=field.maximum,
                              step=field.step or 0.001, hint=field.hint or None)

    def _link_menu_shown(self, field: PlacementField, choices: tuple[str, ...]) -> bool:
        """A menu of one choice is hidden; so is a menu of any moving link on a robot with
        one arm on a fixed base (the constrained link is then the one that matters)."""
        robot = self.app.robot
        if len(choices) < 2:
            return False
        return (field.links == "constrained" or len(robot.ee_frames) > 1
                or robot.root_joint != "fixed")

    def _chosen_link(self, kind: str) -> str | None:
        """The link chosen in ``kind``'s link menu (None: none to choose, or no menu)."""
        kind_type = CONSTRAINT_TYPES[kind]
        links = [field for field in kind_type.placement if field.type == "link"]
        if not links:
            return None
        value = self.constraint_inputs[kind][links[0].name].value
        return value if value in link_choices(self.app.robot, links[0]) else None

    def _placed_on(self, kind: str) -> str | None:
        """The link a new ``kind`` goes on: the one chosen, else the first constrained."""
        chosen = self._chosen_link(kind)
        return chosen if chosen is not None else next(iter(self.app.robot.constrained_links),
                                                      None)

    def _show_applicable_inputs(self, kind: str) -> None:
        """On the chosen link, show the inputs that apply (a distance on a link with an
        instrument axis, a point in link coordinates on one without)."""
        link = self._placed_on(kind)
        for field in CONSTRAINT_TYPES[kind].placement:
            if field.type in ("distance", "link_point"):
                self.constraint_inputs[kind][field.name].visible = \
                    field_applies(field, self.app.robot, link)

    def _adder(self, kind: str):
        """The callback of ``kind``'s "Add" button."""
        return lambda event: self._guarded(event, lambda: self._add_constraint(kind))

    def _add_constraint(self, kind: str) -> str:
        """Place a ``kind`` from its inputs' values (those that apply on the chosen link)."""
        chosen, link = self._chosen_link(kind), self._placed_on(kind)
        values = {}
        for field in CONSTRAINT_TYPES[kind].placement:
            if field.type == "link":
                values[field.name] = chosen
            elif field_applies(field, self.app.robot, link):
                values[field.name] = self.constraint_inputs[kind][field.name].value
        return self.app.add_constraint(kind, **values)

    def _list_placed(self, ids: tuple[str, ...]) -> None:
        """The "placed" menu lists ``ids`` (or says none)."""
        options = ids or (NONE,)
        if tuple(self.constraint_menu.options) != options:
            self.constraint_menu.options = options
