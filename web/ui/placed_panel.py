"""The panel of one kind of placed item (issue 34, the placed-item type): the constraints
(docs/design.md section 5.5) and the obstacles (section 18) are placed, listed, removed
and cleared the same way, so one panel serves both. Per kind, a folder with the kind's
form (an input per field) and an "Add <label>" button; then the placed ones in a menu,
a "Remove" and a "Clear" button. What the inputs are and how their values are read is
the kind's form (:class:`web.ui.constraint_form.ConstraintForm`,
:class:`web.ui.obstacle_form.ObstacleForm`): no kind is named here."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import viser

#: what an empty menu shows
NONE = "(none)"


class KindForm(Protocol):
    """The inputs of one kind of placed item, built in its folder."""

    #: the kind as the operator reads it ("hole", "sphere")
    label: str
    #: the folder's title, whether it opens expanded, the "Add" button's hint
    folder: str
    expanded: bool
    hint: str | None
    #: field name -> its input (after :meth:`build`)
    inputs: dict[str, viser.GuiInputHandle[Any]]

    def build(self, gui: viser.GuiApi) -> None:
        """Add the inputs where ``gui``'s context puts them."""

    def values(self) -> dict[str, object]:
        """The values to place one with, read from the inputs."""


@dataclass(frozen=True)
class PlacedActions:
    """What the panel's buttons do to the session (each posted through the inbox):
    ``add(kind, values)`` places one and gives its id, ``remove(id)`` and ``clear()``."""

    add: Callable[[str, dict[str, object]], str]
    remove: Callable[[str], object]
    clear: Callable[[], object]


@dataclass(frozen=True)
class PlacedWords:
    """The panel's labels: the menu of the placed ones and its two buttons."""

    menu: str
    remove: str
    clear: str


class PlacedPanel:
    """The folders of ``forms`` (kind -> its form), each with its "Add" button, then the
    menu of the placed ones (:meth:`show_placed`), "Remove" and "Clear", built where the
    caller's GUI context puts them; each button's action goes through ``guarded``
    (:meth:`web.ui.TeleopUI._guarded`)."""

    def __init__(self, gui: viser.GuiApi, forms: Mapping[str, KindForm], actions: PlacedActions,
                 words: PlacedWords, guarded: Callable[..., None]) -> None:
        self.forms = dict(forms)
        self._add = actions.add

        def adder(kind: str) -> Callable[[viser.GuiEvent], None]:
            return lambda event: guarded(event, lambda: self.add(kind))

        #: each kind's "Add <label>" button
        self.add_buttons: dict[str, viser.GuiButtonHandle] = {}
        for kind, form in self.forms.items():
            with gui.add_folder(form.folder, expand_by_default=form.expanded):
                form.build(gui)
                self.add_buttons[kind] = gui.add_button(f"Add {form.label}", hint=form.hint)
            self.add_buttons[kind].on_click(adder(kind))
        self.menu = gui.add_dropdown(words.menu, (NONE,))
        self.remove_button = gui.add_button(words.remove)
        self.clear_button = gui.add_button(words.clear)
        self.remove_button.on_click(lambda event: guarded(
            event, lambda: actions.remove(self.menu.value)))
        self.clear_button.on_click(lambda event: guarded(event, actions.clear))

    @property
    def inputs(self) -> dict[str, dict[str, viser.GuiInputHandle[Any]]]:
        """Each kind's inputs by field name."""
        return {kind: form.inputs for kind, form in self.forms.items()}

    def add(self, kind: str) -> str:
        """Place a ``kind`` from its inputs (what its "Add" button does); its id."""
        return self._add(kind, self.forms[kind].values())

    def show_placed(self, ids: tuple[str, ...]) -> None:
        """The menu lists ``ids`` (or says none)."""
        options = ids or (NONE,)
        if tuple(self.menu.options) != options:
            self.menu.options = options
