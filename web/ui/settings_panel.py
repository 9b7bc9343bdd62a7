"""The Settings tab: the drift gain, the damping, the orientation weight, the rate, the
scenes (saved and loaded by name in the scene folder) and the recording."""

from __future__ import annotations

from collections.abc import Callable

import viser

from ..app import TeleopApp
from .inputs import assign


class SettingsPanel:
    """The Settings tab of :class:`web.ui.TeleopUI`, a component owning its inputs, built
    where the caller's GUI context puts them. Each action goes through ``guarded``
    (:meth:`web.ui.TeleopUI._guarded`); ``loaded()`` sets every part of the page from the
    app after a scene was loaded (this tab's inputs included, :meth:`from_app`)."""

    def __init__(self, gui: viser.GuiApi, app: TeleopApp, guarded: Callable[..., None],
                 loaded: Callable[[], None]) -> None:
        self.app = app
        self._loaded = loaded
        self.gain_slider = gui.add_slider("drift gain K (1/s)", 0.0, 500.0, 5.0, app.robots.gain)
        self.damping_slider = gui.add_slider("damping lambda", 0.0, 0.2, 0.001, app.robots.damping)
        self.orientation_slider = gui.add_slider(
            "orientation weight", 0.0, 1.0, 0.05, app.robots.orientation_weight,
            hint="weight of the tools' orientations against their tip positions: lower it "
                 "when two trocars on one torso leave too few joints for both full poses")
        self.rate_number = gui.add_number("rate (Hz)", app.robots.config.rate, min=50, max=5000, step=50)
        self.scene_path = gui.add_text(
            "scene name", "scene.json",
            hint=f"a file name in the scene folder ({app.scene_dir.name}/, set by `teleop "
                 "web --scene-dir`): no folders, nothing outside it")
        self.save_scene_button = gui.add_button("Save scene")
        self.load_scene_button = gui.add_button("Load scene")
        self.scene_status = gui.add_markdown("")
        self.record_button = gui.add_button("Start recording")
        self.record_status = gui.add_markdown("not recording")

        self.gain_slider.on_update(lambda event: guarded(
            event, lambda: app.robots.set_gain(self.gain_slider.value), key="gain", throttled=True))
        self.damping_slider.on_update(lambda event: guarded(
            event, lambda: app.robots.set_damping(self.damping_slider.value), key="damping"))
        self.orientation_slider.on_update(lambda event: guarded(
            event, lambda: app.robots.set_orientation_weight(self.orientation_slider.value),
            key="orientation weight", throttled=True))
        self.rate_number.on_update(lambda event: guarded(
            event, lambda: app.robots.set_rate(self.rate_number.value), key="rate", throttled=True))
        self.save_scene_button.on_click(lambda event: guarded(
            event, self.save_scene, throttled=True))
        self.load_scene_button.on_click(lambda event: guarded(
            event, self.load_scene, throttled=True))
        self.record_button.on_click(lambda event: guarded(event, self.toggle_recording))

    def save_scene(self) -> None:
        """The scene saved under the name typed."""
        path = self.app.scenes.save(self.scene_path.value)
        self.scene_status.content = f"saved `{path.name}`"

    def load_scene(self) -> None:
        """The scene of the name typed loaded, the page set from it."""
        name = self.scene_path.value
        self.app.scenes.load(name)
        self._loaded()
        self.scene_status.content = f"loaded `{self.app.scenes.folder.name_of(name)}`"

    def from_app(self) -> None:
        """The inputs as the app has them (after loading a scene)."""
        app = self.app
        assign(self.gain_slider, app.robots.gain)
        assign(self.damping_slider, app.robots.damping)
        assign(self.orientation_slider, app.robots.orientation_weight)
        assign(self.rate_number, app.robots.config.rate)

    def toggle_recording(self) -> None:
        """Start recording, or stop and say where it was written."""
        if not self.app.recorder.active:
            path = self.app.start_recording()
            self.record_button.label = "Stop recording"
            self.record_status.content = f"recording to `{path.name}`"
        else:
            path = self.app.stop_recording()
            self.record_button.label = "Start recording"
            self.record_status.content = f"wrote `{path}` (replay: `teleop replay {path}`)"
