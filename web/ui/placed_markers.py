"""The scene nodes of one kind of placed item (issue 34, the placed-item type): the
constraints (docs/design.md section 5.3, Markers) and the obstacles (section 18) are
drawn, moved by their gizmo, redrawn and removed the same way, so one class serves both.
What an item's nodes are and how they follow its drawing is its drawer's
(:class:`web.ui.markers.ConstraintDrawer`, :class:`web.ui.collision_view.ObstacleDrawer`).

An item is redrawn only when what it is drawn from moved by :data:`DRAWING_RESOLUTION`
or more since it was last drawn (the view thread shares the interpreter with the 1 kHz
control loop)."""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import viser

#: an item whose drawing moved less than this (m, and rotation entries) is not redrawn
DRAWING_RESOLUTION = 1e-7


class ItemDrawer(Protocol):
    """How one kind of placed item is drawn from its drawing (a snapshot's entry)."""

    def create(self, name: str, entry_id: str, drawing: Any) -> dict[str, Any]:
        """The item's scene nodes under ``name``, by role (``"shape"``...)."""

    def state(self, drawing: Any) -> np.ndarray:
        """What the nodes are drawn from, as one vector."""

    def update(self, nodes: dict[str, Any], drawing: Any) -> None:
        """The nodes moved to ``drawing``."""


@dataclass(frozen=True)
class Gizmos:
    """Each placed item's gizmo (drawn over the links, ``scale`` m): its drags go through
    ``guarded`` (:meth:`web.ui.TeleopUI._guarded`) as ``move(id, position)``, the latest
    per item winning (the inbox key ``(key, id)``)."""

    move: Callable[[str, np.ndarray], object]
    guarded: Callable[..., None]
    key: str
    scale: float = 0.07


class PlacedMarkers:
    """The placed items of one kind drawn under ``prefix`` by ``drawer``: :attr:`nodes`
    maps an item's id to its scene nodes; given ``gizmos``, each has its gizmo."""

    def __init__(self, server: viser.ViserServer, prefix: str, drawer: ItemDrawer,
                 gizmos: Gizmos | None = None) -> None:
        self.server = server
        self.prefix = prefix
        self.drawer = drawer
        self.gizmos = gizmos
        self.nodes: dict[str, dict[str, Any]] = {}
        self._drawn: dict[str, np.ndarray] = {}

    def draw(self, drawings: Mapping[str, Any], goals: Mapping[str, np.ndarray]) -> None:
        """The items of ``drawings`` (id -> drawing) drawn, those gone removed; a new
        item's gizmo starts at its goal in ``goals``."""
        for entry_id in [entry_id for entry_id in self.nodes if entry_id not in drawings]:
            for handle in self.nodes.pop(entry_id).values():
                handle.remove()
            self._drawn.pop(entry_id, None)
        for entry_id, drawing in drawings.items():
            nodes = self.nodes.get(entry_id)
            if nodes is None:
                nodes = self.nodes[entry_id] = self._create(entry_id, drawing, goals[entry_id])
                self._drawn.pop(entry_id, None)
            state = self.drawer.state(drawing)
            last = self._drawn.get(entry_id)
            if last is None or last.shape != state.shape or \
                    float(np.max(np.abs(state - last))) >= DRAWING_RESOLUTION:
                self.drawer.update(nodes, drawing)
                self._drawn[entry_id] = state

    def _create(self, entry_id: str, drawing: Any, goal: np.ndarray) -> dict[str, Any]:
        """An item's nodes and, given gizmos, its gizmo at ``goal``."""
        name = f"{self.prefix}/{node_name(entry_id)}"
        nodes = self.drawer.create(name, entry_id, drawing)
        gizmos = self.gizmos
        if gizmos is None:
            return nodes
        handle = self.server.scene.add_transform_controls(
            f"{name}/gizmo", scale=gizmos.scale, position=goal, disable_rotations=True,
            depth_test=False)
        key = (gizmos.key, entry_id)

        @handle.on_update
        def _(event: viser.TransformControlsEvent) -> None:
            position = np.array(handle.position)
            gizmos.guarded(event, lambda: gizmos.move(entry_id, position), key=key)

        nodes["gizmo"] = handle
        return nodes

    def remove(self) -> None:
        """Every item's nodes removed (a loaded scene's are drawn afresh)."""
        for nodes in self.nodes.values():
            for handle in nodes.values():
                handle.remove()
        self.forget()

    def forget(self) -> None:
        """Every item forgotten, its nodes left to whoever removes their parent (the
        ghost's root)."""
        self.nodes.clear()
        self._drawn.clear()


def node_name(name: str) -> str:
    """A link, item or pair name as one scene-node name (no ``/``, no spaces): a pair
    ``"a | b"`` becomes ``"a--b"``."""
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name.replace(" | ", "--"))
