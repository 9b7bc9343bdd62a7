"""The input devices in the page (docs/design.md section 19): the operator's view
follows the browser's camera, a choice of orientation mapping, each device's state in
the status, and the feedback force it renders, plotted."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
import viser
import viser.uplot as uplot

from ..app import HISTORY_SECONDS, TeleopApp
from .plots import axes_labelled

#: the feedback plot's lines: the force along the device's x (right), y (up), z (back)
FEEDBACK_COLORS = ("#dc2626", "#16a34a", "#2563eb")
ORIENTATIONS = ("relative", "absolute")


def device_words(device: dict, ee_name: str, rate: float | None) -> str:
    """A device's line of the status: its state, what it received and dropped, the
    arrival-to-command latency, the force it renders."""
    stats = device["source"].statistics(window=4096)
    words = f"**input {device['name']}** ({ee_name}) {device['reason']}"
    if device["source"].problem:
        words += f" (**{device['source'].problem}**)"
    intrusions = getattr(device["source"], "intrusions", None)
    warning = intrusions() if intrusions is not None else ""
    if warning:
        words += f" (**{warning}**)"
    if stats.get("received"):
        dropped = ", ".join(f"{reason.replace('_', ' ')} {stats[reason]}"
                            for reason in stats["drop_reasons"] if stats.get(reason))
        words += (f"; {stats['received']} received" + (f" ({rate:.0f}/s)" if rate else "")
                  + f", {stats.get('applied', 0)} applied, {stats.get('superseded', 0)} "
                  f"superseded, {stats['dropped']} dropped{' (' + dropped + ')' if dropped else ''}"
                  f", {stats.get('lost', 0)} lost")
    if not math.isnan(stats["latency_p50_ms"]):
        words += (f"; latency arrival-to-command p50 {stats['latency_p50_ms']:.2f} ms, "
                  f"p99 {stats['latency_p99_ms']:.2f} ms")
    if device["source"].renders_feedback:
        words += f"; feedback |F| {np.linalg.norm(device['wrench'][:3]):.2f} N"
    return words


class DevicePanel:
    """The devices' part of :class:`web.ui.TeleopUI`, a component owning its handles: the
    orientation mapping menu (built where the caller's GUI context puts it; the gizmo's
    mapping is always relative), the feedback force plot, each browser camera's reports
    handed to the app as the operator's view, and the devices' status lines.

    Parameters
    ----------
    server : the viser server.
    app : the session (its devices' ``set_orientation_mode`` and ``set_view``).
    ee_names : what the operator reads per EE frame.
    guarded : posts an operator action (``guarded(event, action, key=...)``,
        :meth:`web.ui.TeleopUI._guarded`).
    """

    def __init__(self, server: viser.ViserServer, app: TeleopApp, ee_names: dict[str, str],
                 guarded: Callable[..., None]) -> None:
        self.server = server
        self.app = app
        self.ee_names = ee_names
        self._guarded = guarded
        self._feedback_plot: viser.GuiUplotHandle | None = None
        self._received: dict[str, tuple[float, int]] = {}
        self.orientation_menu = self.server.gui.add_dropdown(
            "device orientation", ORIENTATIONS, initial_value=ORIENTATIONS[0],
            hint="relative: the tool turns by the device's rotation since it was coupled; "
                 "absolute: the tool's orientation in the view is the device's")
        self.orientation_menu.on_update(lambda event: self._guarded(
            event, lambda: self.app.devices.set_orientation_mode(
                self.orientation_menu.value == "absolute"), key="orientation"))
        self.server.on_client_connect(self._watch_view)

    def _watch_view(self, client: viser.ClientHandle) -> None:
        """The devices move in the view of the browser whose camera moved last; a new
        browser's view counts from its first camera report."""
        camera = client.camera
        camera.on_update(lambda _: self._guarded(
            None, lambda wxyz=np.array(camera.wxyz): self.app.devices.set_view(wxyz), key="view"))
        self._guarded(None, lambda wxyz=np.array(camera.wxyz): self.app.devices.set_view(wxyz),
                      key="view")

    def lines(self, snapshot: dict) -> list[str]:
        """Each device's status line; its rate of commands received since the previous
        line, over the wall clock (the loop's time lags it when the loop falls behind)."""
        frames = snapshot["ee_frames"]
        lines = []
        now = time.monotonic()
        for device in snapshot["devices"]:
            count = device["source"].counts["received"]
            before = self._received.get(device["name"])
            rate = None if before is None or now <= before[0] else \
                (count - before[1]) / (now - before[0])
            self._received[device["name"]] = (now, count)
            lines.append(device_words(device, self.ee_names[frames[device["ee"]]], rate))
        return lines

    def draw_plot(self, snapshot: dict, tab: viser.GuiTabHandle, order: float) -> None:
        """The force the first feedback-rendering device renders, in its frame, in the
        plots' ``tab`` at ``order`` (added there the first time)."""
        shown = [d for d in snapshot["devices"] if d["source"].renders_feedback]
        if not shown or len(shown[0]["history"]) < 2:
            return
        history = np.array(shown[0]["history"])
        data = (history[:, 0] - snapshot["robots"]["main"]["t"],
                history[:, 1], history[:, 2], history[:, 3])
        if self._feedback_plot is not None:
            self._feedback_plot.data = data
            return
        with tab:
            self._feedback_plot = self.server.gui.add_uplot(
                data=data, title=f"feedback force, {shown[0]['name']} (N, device frame)",
                series=(uplot.Series(label="t - now (s)"),
                        *[uplot.Series(label=axis, stroke=color, width=1.5)
                          for axis, color in zip(("x right", "y up", "z back"),
                                                 FEEDBACK_COLORS)]),
                aspect=2.0, order=order,
                scales={"x": uplot.Scale(time=False, auto=False,
                                         range=(-HISTORY_SECONDS, 0.0)),
                        "y": uplot.Scale(auto=True)},
                axes=axes_labelled("N"))
