"""End to end: ``teleop web --robot .../panda.urdf`` (example-robot-data) in a real Chromium.

Its visual meshes are COLLADA (``.dae``): they are drawn with their materials (trimesh
reads them through pycollada), and a hole on the forearm holds. Its own module: one
browser at a time (Playwright's sync API runs one instance per thread).
"""

from __future__ import annotations

import time

import numpy as np
from browser_helpers import (  # noqa: F401 (watchdog: an autouse fixture)
    WAIT,
    PANDA,
    changed_fraction,
    click_add_hole,
    distinct_colours,
    open_web,
    set_camera,
    wait_for_pixels,
    watchdog,
)

from teleop import load_robot


def test_the_panda_opens_with_its_meshes(tmp_path):
    panda = load_robot(PANDA, ee_frame="panda_hand", constrained_link="panda_link4",
                       link_axis=(-0.0825, 0.384, 0.0))
    with open_web(panda, tmp_path) as web:
        view = web.ui.scene.views["main"]
        assert view.problems == [] and web.ui.notes == []
        names = [g.name for g in panda.visual_model.geometryObjects]
        assert len(names) == 11
        for name in names:  # each .dae drawn as a glTF with its materials
            assert type(view.frames[f"/main/visual/{name}"]).__name__ == "GlbHandle"
        target = web.app.console.target.translation
        set_camera(web.client, target + np.array([0.9, -0.9, 0.3]), target - [0.0, 0.0, 0.3])
        shown = wait_for_pixels(web, lambda p: distinct_colours(p) > 100, WAIT, "the Panda")
        view.displayVisuals(False)
        try:
            hidden = wait_for_pixels(web, lambda p: changed_fraction(p, shown) > 0.01, WAIT,
                                     "the canvas to change when the Panda is hidden")
        finally:
            view.displayVisuals(True)
        print(f"\n[browser] the Panda covers {100 * changed_fraction(hidden, shown):.1f} % of "
              f"the canvas")
        hole_id = click_add_hole(web)  # and a hole on its forearm holds
        time.sleep(0.5)
        assert web.app.constraints.entries[hole_id].kind == "hole"
        assert web.app.robots.last_records["main"].constraint_error < 1e-6
        assert web.page_errors == [], web.page_errors
