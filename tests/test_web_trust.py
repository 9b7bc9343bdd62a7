"""What the UI core refuses and how it holds up: files only in their folders,
targets and settings bounded, a flood of events that does not starve the control loop, a
browser lost mid-drag that leaves the robot settling, the loop falling behind said."""

from __future__ import annotations

import json
import os
import time

import numpy as np
import pinocchio as pin
import pytest
from browser_helpers import wait_for

from web.app import (
    BEHIND_FRACTION,
    MAX_DAMPING,
    MAX_TARGET_DISTANCE,
    ControlThread,
    TeleopApp,
    behind_words,
)
from web.inbox import MAX_PENDING, THROTTLE, Inbox


@pytest.fixture()
def app(sda10f, tmp_path):
    return TeleopApp(sda10f, controller="cjm", record_dir=tmp_path / "recordings",
                     scene_dir=tmp_path / "scenes")


def run(app, seconds):
    for _ in range(int(seconds * app.robots.config.rate)):
        app.step()


def files_under(folder) -> set[str]:
    return {os.path.relpath(os.path.join(root, name), folder)
            for root, _, names in os.walk(folder) for name in names}


# -- files: inside their folders, nothing else -----------------------------------------------


def outside_names(tmp_path) -> list[str]:
    """Names that point out of the scene folder: each refused."""
    outside = tmp_path / "outside"
    outside.mkdir(exist_ok=True)
    (outside / "secret.json").write_text("{}")
    scenes = tmp_path / "scenes"
    scenes.mkdir(exist_ok=True)
    (scenes / "linked").symlink_to(outside, target_is_directory=True)
    (scenes / "linked.json").symlink_to(outside, target_is_directory=True)
    (scenes / "leak.json").symlink_to(outside / "secret.json")
    (scenes / "dangling.json").symlink_to(outside / "new.json")
    return ["../x.json", "../outside/secret.json", str(outside / "x.json"), "/etc/passwd",
            "linked/x.json", "linked", "linked.json", "leak.json", "x.sh", ".json", ".x.json",
            "dangling.json", "..", ".", "a\\b.json",
            "C:x.json", "x\0.json", "~/x.json", "", "   ", "a" * 300]


def test_scenes_are_read_and_written_only_in_the_scene_folder(app, tmp_path):
    names = outside_names(tmp_path)
    before = files_under(tmp_path)
    for name in names:
        with pytest.raises(ValueError, match="scene name .* refused") as refused:
            app.scenes.save(name) if name.strip() else app.scenes.folder.writable(name)
        assert "secret" not in str(refused.value) or "secret" in name
        with pytest.raises(ValueError, match="scene name .* refused"):
            app.scenes.load(name)
    assert files_under(tmp_path) == before  # nothing written anywhere
    assert not (tmp_path / "outside" / "new.json").exists()
    assert not (tmp_path / "x.json").exists()
    saved = app.scenes.save("mine.json")  # a plain name goes in the folder
    assert saved == tmp_path / "scenes" / "mine.json" and saved.is_file()
    app.scenes.load("mine.json")


def test_saving_over_a_hard_link_in_the_scene_folder_leaves_the_file_outside_untouched(app,
                                                                                      tmp_path):
    """A hard link cannot be told from a file by its path: the save replaces the name (a new
    file renamed over it), so the file outside keeps its content and the folder holds the
    scene, and no scratch file is left behind."""
    outside = tmp_path / "outside.json"
    outside.write_text('{"mine": true}\n')
    app.scene_dir.mkdir(parents=True, exist_ok=True)
    os.link(outside, app.scene_dir / "linked.json")
    saved = app.scenes.save("linked.json")
    assert outside.read_text() == '{"mine": true}\n'
    assert os.stat(outside).st_nlink == 1 and not os.path.samefile(saved, outside)
    assert json.loads(saved.read_text()) == json.loads(json.dumps(app.scenes.scene()))
    assert sorted(p.name for p in app.scene_dir.iterdir()) == ["linked.json"]


def test_a_refusal_says_nothing_about_what_is_outside(app, tmp_path):
    """A missing outside file and an outside file that is not JSON are refused alike."""
    (tmp_path / "notjson.json").write_text("{nope")
    messages = []
    for name in ("../notjson.json", "../missing.json", str(tmp_path / "notjson.json"),
                 str(tmp_path / "missing.json")):
        with pytest.raises(ValueError) as refused:
            app.scenes.load(name)
        messages.append(str(refused.value).replace(name, "NAME"))
    assert len(set(messages[:2])) == 1 and len(set(messages[2:])) == 1, messages
    assert not any("JSON" in m or "no scene" in m for m in messages)


def test_recordings_go_only_to_the_recording_folder(app, tmp_path):
    for name in outside_names(tmp_path):
        with pytest.raises(ValueError, match="recording name .* refused"):
            app.start_recording(name) if name.strip() else app.recordings.writable(name)
        assert not app.recorder.active
    path = app.start_recording("take-1.jsonl")
    assert path == tmp_path / "recordings" / "take-1.jsonl"
    run(app, 0.01)
    app.stop_recording()
    assert path.is_file() and json.loads(path.read_text().splitlines()[0])


def test_a_recording_never_replaces_another(app, tmp_path):
    """Two recordings started within one second get two files (the default name is by the
    second); a name already in the folder is refused and the file stays as it was."""
    first = app.start_recording()
    run(app, 0.01)
    app.stop_recording()
    kept = first.read_bytes()
    second = app.start_recording()
    app.stop_recording()
    assert second != first and second.parent == first.parent
    assert first.read_bytes() == kept
    with pytest.raises(ValueError, match=f"{first.name!r} is already in the recording folder"):
        app.start_recording(first.name)
    assert not app.recorder.active and first.read_bytes() == kept


def test_a_symlink_loop_is_refused_like_any_name_leading_out(app, tmp_path):
    folder = tmp_path / "scenes"
    folder.mkdir(exist_ok=True)
    (folder / "loop.json").symlink_to(folder / "loop.json")
    for action in (app.scenes.load, app.scenes.save):
        with pytest.raises(ValueError, match=r"scene name 'loop.json' refused") as refused:
            action("loop.json")
        assert str(tmp_path) not in str(refused.value)


# -- nonsense: bounded targets and settings ---------------------------------------------------


@pytest.mark.parametrize("action, message", [
    (lambda app: app.console.set_target([1e300, 0, 0], [1, 0, 0, 0]), "target refused: .* more than 2 m"),
    (lambda app: app.console.set_target([np.nan, 0, 0], [1, 0, 0, 0]), "target position must be finite"),
    (lambda app: app.console.set_target(app.console.target.translation + [0, 0, 2.5], [1, 0, 0, 0]),
     "target refused"),
    (lambda app: app.console.move_gizmo([0, 1e300, 0], [1, 0, 0, 0]), "gizmo's target refused"),
    (lambda app: app.console.move_gizmo([0, np.inf, 0], [1, 0, 0, 0]), "gizmo position must be finite"),
    (lambda app: app.robots.set_damping(1e300), "damping must be <= 1"),
    (lambda app: app.robots.set_damping(np.nan), "damping must be finite"),
    (lambda app: app.robots.set_gain(1e300), "gain must be in"),
    (lambda app: app.robots.set_gain("abc"), "gain must be a number"),
    (lambda app: app.robots.set_rate(1e12), "rate must be between 50 and 5000 Hz"),
    (lambda app: app.robots.set_rate(True), "rate must be a number"),
    (lambda app: app.constraints.move(app.constraints.add("hole", distance=0.08), [1e300, 0, 0]),
     "constraint position refused"),
])
def test_a_target_or_setting_out_of_range_is_refused_naming_it(app, action, message):
    target, gizmo = app.console.target.copy(), app.console.gizmo.copy()
    settings = (app.robots.gain, app.robots.damping, app.robots.config.rate)
    with pytest.raises(ValueError, match=message):
        action(app)
    assert app.console.target.isApprox(target, 0.0) and app.console.gizmo.isApprox(gizmo, 0.0)
    assert (app.robots.gain, app.robots.damping, app.robots.config.rate) == settings
    run(app, 0.01)
    assert np.isfinite(app.robots.loops["main"].q).all()


def test_targets_within_the_maximum_distance_are_taken(app):
    ee = app.robots.loops["main"].ee_placement()
    inside = ee.translation + [0.0, 0.0, 0.99 * MAX_TARGET_DISTANCE]
    app.console.set_target(inside, [1, 0, 0, 0])
    np.testing.assert_array_equal(app.console.target.translation, inside)
    app.robots.set_damping(MAX_DAMPING)
    assert app.robots.damping == MAX_DAMPING


def test_the_app_refuses_a_rate_out_of_range_at_construction(sda10f, tmp_path):
    with pytest.raises(ValueError, match="rate must be between 50 and 5000 Hz, got 1e\\+12"):
        TeleopApp(sda10f, rate=1e12, record_dir=tmp_path)


# -- the inbox: latest wins, throttled, bounded --------------------------------------------------


def test_the_inbox_keeps_the_latest_value_per_key_and_the_order_of_actions():
    applied, errors = [], []
    inbox = Inbox(lambda context, error: errors.append((context, str(error))))
    for value in range(100):  # not started: everything waits
        inbox.post(lambda v=value: applied.append(("slider", v)), key="slider")
    inbox.post(lambda: applied.append(("click", 1)))
    inbox.post(lambda: applied.append(("click", 2)))
    inbox.post(lambda: (_ for _ in ()).throw(ValueError("no")), context="browser 3")
    inbox.start()
    try:
        assert inbox.drain(10.0)
    finally:
        inbox.stop()
    assert applied == [("slider", 99), ("click", 1), ("click", 2)]
    assert errors == [("browser 3", "no")] and inbox.coalesced == 99


def test_the_inbox_throttles_and_bounds_what_waits():
    times, errors = [], []
    inbox = Inbox(lambda context, error: errors.append(str(error)))
    inbox.start()
    try:
        end = time.monotonic() + 1.0
        while time.monotonic() < end:  # a throttled setting changed without pause for 1 s
            inbox.post(lambda: times.append(time.monotonic()), key="rate", throttled=True)
            time.sleep(0.001)
        assert inbox.drain(10.0)
    finally:
        inbox.stop()
    gaps = np.diff(times)
    assert len(times) <= 1.0 / THROTTLE + 2 and gaps.min() >= THROTTLE - 1e-3, gaps
    refused = Inbox(lambda context, error: errors.append(str(error)))  # never started
    assert all(refused.post(lambda: None) for _ in range(MAX_PENDING))
    assert not refused.post(lambda: None) and "too many actions" in errors[-1]
    assert refused.post(lambda: None, key="slider") is False  # a new key too


# -- a flood of events does not starve the control loop -----------------------------------------


def test_a_flood_of_10000_events_in_5_s_does_not_starve_the_control_loop(app):
    """10,000 operator events in 5 s, half of them rate changes (each a rebuild of every
    controller), through the inbox, with the control thread running: the rate changes
    coalesce to at most one rebuild per 100 ms and the loop keeps ticking.

    Asserted: no starvation, at least one tick per 10 ms on average over the flood (the
    old behaviour, a rebuild per event under the lock, fell to 4-14 Hz). The achieved rate
    is printed (docs/design.md section 5.3 has the measure)."""
    app.constraints.add("hole", distance=0.08)
    inbox = Inbox(lambda context, error: None)
    control = ControlThread(app)
    control.start()
    inbox.start()
    rebuilds = []
    original = app.robots.make_loop

    def counted(*args, **kwargs):
        rebuilds.append(time.monotonic())
        return original(*args, **kwargs)

    app.robots.make_loop = counted
    try:
        time.sleep(1.0)
        ticks0, start = app.ticker.ticks, time.monotonic()
        ee = app.robots.loops["main"].ee_placement()
        wxyz = pin.Quaternion(ee.rotation)
        for k in range(10_000):
            if k % 2:
                inbox.post(lambda k=k: app.robots.set_rate(990.0 if k % 4 == 1 else 1000.0),
                           key="rate", throttled=True)
            else:
                position = ee.translation + 0.01 * np.array([np.sin(k / 300), 0.0, 0.0])
                inbox.post(lambda p=position: app.console.move_gizmo(p, [wxyz.w, wxyz.x, wxyz.y, wxyz.z]),
                           key="gizmo")
            time.sleep(max(0.0, start + 5e-4 * (k + 1) - time.monotonic()))
        flood = time.monotonic() - start
        ticks = app.ticker.ticks - ticks0
        assert inbox.drain(10.0)
    finally:
        app.robots.make_loop = original
        inbox.stop()
        control.stop()
    rate = ticks / flood
    print(f"\n[flood] 10000 events in {flood:.2f} s: {ticks} ticks, {rate:.0f} Hz achieved "
          f"(target 990-1000 Hz as the rate flips), {len(rebuilds)} loop builds, "
          f"{inbox.coalesced} events coalesced, {control.deadline_misses} deadline misses")
    assert control.error is None and np.isfinite(app.robots.loops["main"].q).all()
    assert rate >= 100.0, f"the control loop starved: {rate:.0f} Hz during the flood"
    # at most one rebuild per 100 ms (the drain included)
    assert len(rebuilds) <= (flood + 10.0) / THROTTLE


# -- a browser lost mid-drag ----------------------------------------------------------------------


def test_a_target_held_where_the_robot_is_lets_it_settle(app):
    """A drag past the joint limits, then the browser lost: held where the EE is, the robot
    stops; left at the drag's end (the old behaviour), it creeps on along the limits."""
    robot = app.robot
    ee = app.robots.loops["main"].ee_placement()
    wxyz = pin.Quaternion(ee.rotation)
    far = ee.translation + [0.6, 0.3, -0.4]  # out of reach: the joints run to their limits
    app.console.set_target(far, [wxyz.w, wxyz.x, wxyz.y, wxyz.z])
    run(app, 3.0)
    left = TeleopApp(robot, record_dir=app.record_dir, scene_dir=app.scene_dir)
    with left._lock, app._lock:
        left.robots.loops["main"].q = app.robots.loops["main"].q.copy()
        left.console.inputs[0].target = app.console.target.copy()
    app.console.hold_where_the_robot_is(0)
    held_at = app.robots.loops["main"].ee_placement().translation
    np.testing.assert_allclose(app.console.target.translation, held_at, atol=1e-12)
    np.testing.assert_allclose(app.console.gizmo.translation, held_at, atol=1e-12)
    run(app, 1.0)
    run(left, 1.0)
    q_held, q_left = app.robots.loops["main"].q.copy(), left.robots.loops["main"].q.copy()
    run(app, 1.0)
    run(left, 1.0)
    held_speed = np.abs(app.robots.loops["main"].q - q_held).max()  # rad in the last second
    left_speed = np.abs(left.robots.loops["main"].q - q_left).max()
    print(f"\n[lost client] joint motion in the second second: held {held_speed:.2e} rad/s, "
          f"left at the drag's end {left_speed:.2e} rad/s")
    assert np.linalg.norm(app.robots.loops["main"].ee_placement().translation - held_at) < 5e-3
    # settling, at least a hundred times slower than the creep it replaces, and slowing
    assert held_speed < 1e-2 * left_speed, (held_speed, left_speed)
    q_later = app.robots.loops["main"].q.copy()
    run(app, 1.0)
    assert np.abs(app.robots.loops["main"].q - q_later).max() < held_speed


# -- the loop falling behind ---------------------------------------------------------------------


def test_behind_is_said_below_95_percent_of_the_rate():
    assert behind_words(1000.0, 1000.0) == "" and behind_words(950.0, 1000.0) == ""
    words = behind_words(949.0, 1000.0)
    assert "only 949 of the 1000 Hz asked for" in words and "(95 %)" in words
    assert "only 84 of the 1000 Hz asked for (8 %)" in behind_words(84.0, 1000.0)
    assert BEHIND_FRACTION == 0.95


def test_a_control_thread_that_cannot_keep_its_rate_says_so(app, monkeypatch):
    step = app.step

    def slow_step():  # 2.5 ms a tick: at most 400 Hz of the 1000 asked for
        time.sleep(2.5e-3)
        return step()

    monkeypatch.setattr(app, "step", slow_step)
    control = ControlThread(app)
    assert control.behind() == ""  # nothing measured yet
    control.start()
    try:
        words = wait_for(control.behind, 10.0)
    finally:
        control.stop()
    assert control.achieved_rate < 0.95 * 1000.0
    assert words.startswith("control loop behind:") and "of the 1000 Hz" in words


