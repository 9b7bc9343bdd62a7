"""What the UI's control tick does and does not do (docs/design.md section 5.3; docs/ui.md,
"The tick's cost"): structural properties, counted rather than timed. The control thread
computes no collision rows of its own (the view reads those the controllers held); the view
takes only copies under the lock the control thread needs, and draws, words and serialises
without it; the measures are taken at the history rate; the status's split of the tick is
the tick's own (controllers within the loops' hot path within the tick)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pinocchio as pin
import pytest
import viser
from browser_helpers import free_port
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from constraints.collision import CollisionAvoidance
from web.app import HISTORY_RATE, ControlThread, TeleopApp
from web.app.control_thread import percentiles
from web.ui import TeleopUI

#: two computations of the same pair at the same q (as in tests/test_web_collisions.py)
SAME = 1e-12


@pytest.fixture()
def app(sda10f, tmp_path):
    app = TeleopApp(sda10f, record_dir=tmp_path / "sessions", scene_dir=tmp_path / "scenes",
                    ghost="qp:daqp")
    app.constraints.add("hole", distance=0.08)
    tip = app.robots.loops["main"].ee_placements()[0]  # a sphere 2 cm in front of the tip
    app.collisions.add("sphere", radius=0.03, center=tip.translation + 0.05 * tip.rotation[:, 2])
    return app


@pytest.fixture()
def server():
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield server
    server.stop()


def lock_free(app) -> bool:
    """Whether another thread could take the app's lock now (nobody holds it)."""
    taken = []

    def probe() -> None:
        if app._lock.acquire(blocking=False):
            taken.append(True)
            app._lock.release()

    thread = threading.Thread(target=probe)
    thread.start()
    thread.join()
    return bool(taken)


def independent_rows(app, q: np.ndarray):
    """The rows of a new avoidance with the app's settings and obstacles at ``q``."""
    avoidance = CollisionAvoidance.from_dict(app.robot, app.collisions.avoidance.to_dict())
    avoidance.set_ports([entry.constraint for entry in app.constraints.entries.values()])
    data = app.robot.model.createData()
    pin.computeJointJacobians(app.robot.model, data, q)
    return avoidance.rows(app.robot.model, data)


def counted_rows(app, monkeypatch) -> dict[str, int]:
    """Count the avoidance's ``rows`` calls: inside a controller's step, and elsewhere."""
    calls = {"controllers": 0, "elsewhere": 0}
    stepping = threading.local()
    rows = app.collisions.avoidance.rows

    def counting(model, data):
        calls["controllers" if getattr(stepping, "on", False) else "elsewhere"] += 1
        return rows(model, data)

    monkeypatch.setattr(app.collisions.avoidance, "rows", counting)
    for loop in app.robots.loops.values():
        solve = loop.controller.solve

        def stepped(q, twist, solve=solve):
            stepping.on = True
            try:
                return solve(q, twist)
            finally:
                stepping.on = False

        monkeypatch.setattr(loop.controller, "solve", stepped)
    return calls


def test_the_control_thread_computes_no_collision_rows_for_the_view(app, monkeypatch):
    calls = counted_rows(app, monkeypatch)
    ticks = 200  # 10 history ticks at 1 kHz
    for _ in range(ticks):
        q = {which: loop.q.copy() for which, loop in app.robots.loops.items()}
        app.step()
    # the ghost (qp:daqp) calls rows once a step; the CJM's compiled step measures its
    # own in C++ (docs/design.md 18.4), no rows call: none elsewhere either way
    assert calls == {"controllers": ticks, "elsewhere": 0}
    # the rows the view reads are the last the controllers held, at the q they were given
    for which in app.robots.loops:
        shown = app.view.snapshot()["robots"][which]["collision_rows"]
        expected = independent_rows(app, q[which])
        assert expected.size >= 1 and shown.pairs == expected.pairs
        np.testing.assert_allclose(shown.distances, expected.distances, atol=SAME)
    assert shown is app.collisions.avoidance.last_rows  # the ghost stepped last: its own rows, no copy


def test_rows_a_controller_did_not_compute_are_measured_on_history_ticks_only(app, monkeypatch):
    """A controller that keeps its pairs apart without the avoidance's ``rows`` (the
    avoidance's ``last_rows`` left as it was): the tick measures them for the view, at
    the history rate, where that controller's command was computed from."""
    ghost = app.robots.loops["ghost"].controller
    solve = ghost.solve

    def rows_elsewhere(q, twist):
        kept = app.collisions.avoidance.last_rows
        try:
            return solve(q, twist)
        finally:
            app.collisions.avoidance.last_rows = kept

    monkeypatch.setattr(ghost, "solve", rows_elsewhere)
    calls = counted_rows(app, monkeypatch)
    ticks = 200
    for _ in range(ticks):
        record = app.robots.last_records["ghost"]
        q = app.robots.loops["ghost"].q.copy()
        app.step()
        if app.robots.last_records["ghost"] is not record:
            measured_at = q
    history = round(ticks * HISTORY_RATE * app.robots.config.dt)
    assert calls == {"controllers": ticks, "elsewhere": history}  # the CJM's rows: in C++
    shown = app.view.snapshot()["robots"]["ghost"]["collision_rows"]
    expected = independent_rows(app, measured_at)
    assert expected.size >= 1 and shown.pairs == expected.pairs
    np.testing.assert_allclose(shown.distances, expected.distances, atol=SAME)


def test_the_measures_are_taken_at_the_history_rate(app, monkeypatch):
    counts = {"measure_command": 0, "measure": 0}
    for loop in app.robots.loops.values():
        for name in counts:
            original = getattr(loop, name)
            monkeypatch.setattr(loop, name, lambda step, f=original, name=name:
                                counts.__setitem__(name, counts[name] + 1) or f(step))
    ticks = 1000
    for _ in range(ticks):
        app.step()
    history = round(ticks * HISTORY_RATE * app.robots.config.dt)
    assert counts == {"measure_command": 2 * history, "measure": 2 * history}
    assert len(app.robots.traces["main"].t) == len(app.robots.traces["ghost"].t) == history


def test_the_view_takes_only_copies_under_the_lock(app, server, monkeypatch):
    """The drawings, the words, the plots' arrays and every message to the browsers are
    made with the lock free: the control thread never waits for them."""
    import web.app.view as view

    free: dict[str, list[bool]] = {"geometry": [], "words": [], "arrays": [], "draw": []}
    geometry = view.constraint_geometry
    monkeypatch.setattr(view, "constraint_geometry",
                        lambda constraint, placement: free["geometry"].append(lock_free(app))
                        or geometry(constraint, placement))
    describe = view.describe_limitation
    monkeypatch.setattr(view, "describe_limitation",
                        lambda *args: free["words"].append(lock_free(app)) or describe(*args))
    arrays_of = view.Trace.arrays_of
    monkeypatch.setattr(view.Trace, "arrays_of",
                        staticmethod(lambda columns: free["arrays"].append(lock_free(app))
                                     or arrays_of(columns)))
    for _ in range(100):
        app.step()
    ui = TeleopUI(server, app, ControlThread(app))
    draw = ui._draw
    monkeypatch.setattr(ui, "_draw", lambda snapshot, status=True:
                        free["draw"].append(lock_free(app)) or draw(snapshot, status))
    ui.start()  # the view thread itself: snapshot, then draw and send
    try:
        deadline = time.monotonic() + 60.0
        while len(free["draw"]) < 3 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        ui.stop()
    details = ui.status_panel.details.content
    assert details.startswith("**control"), details  # no view error
    assert all(len(seen) >= 2 for seen in free.values()), free  # both robots, the view's frames
    assert all(all(seen) for seen in free.values()), free


def test_the_status_split_is_the_ticks_own(app):
    """Per tick: the controllers' steps within the loops' hot path within the whole tick;
    the status's medians are those of the recorded ticks."""
    control = ControlThread(app)
    control.start()
    try:
        deadline = time.monotonic() + 60.0
        while control._count < 600 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        control.stop()
    timing = control.timing()  # of the ticks recorded, none added after it
    n = min(timing.ticks, len(control._tick))
    solve, advance, tick = control._solve[:n], control._advance[:n], 1e6 * control._tick[:n]
    assert n >= 600 and control.error is None
    assert np.all(solve > 0.0) and np.all(solve <= advance) and np.all(advance <= tick)
    assert timing.solve_p50_us == pytest.approx(np.percentile(solve, 50))
    assert timing.loop_p50_us == pytest.approx(np.percentile(advance - solve, 50))
    assert timing.ui_p50_us == pytest.approx(np.percentile(tick - advance, 50))


@given(columns=st.integers(1, 4096).flatmap(lambda n: arrays(
           float, (3, n), elements=st.floats(-1e6, 1e6, allow_nan=False))),
       q=st.sampled_from([0.0, 50.0, 99.0, 100.0]))
def test_the_status_percentiles_are_numpys(columns, q):
    expected = np.percentile(columns, q, axis=1)
    np.testing.assert_allclose(percentiles(columns, q), expected, rtol=1e-12,
                               atol=1e-12 * max(1.0, float(np.abs(columns).max())))
