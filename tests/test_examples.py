"""Every ``examples/*.py`` runs headless to completion and prints the numbers it promises.

Each script runs in a subprocess (this interpreter, a temp working directory, 120 s at
most). The list is the glob of the folder, so a new example is run without touching this
file; the examples below also have their printed numbers checked.
"""

from __future__ import annotations

import json
import os
import re
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from teleop.loop import SupervisorConfig

EXAMPLES_DIR = Path(__file__).resolve().parent.parent / "examples"
EXAMPLES = sorted(EXAMPLES_DIR.glob("*.py"))
TIMEOUT = 120.0  # s, per example
NUMBER = r"([-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)"

#: extra command-line arguments (``{tmp}``: the test's temp directory)
ARGUMENTS = {
    "02_closed_loop.py": ["{tmp}/out", "--seconds", "2"],
    "06_embed_teleop_app.py": ["--seconds", "2"],
}
#: distributions an example needs beyond the package's own dependencies
def numbers(pattern: str, text: str) -> list[float]:
    """Every number captured by ``pattern`` (one group, written with NUMBER) in ``text``."""
    return [float(value) for value in re.findall(pattern.replace("NUMBER", NUMBER), text)]


def check_01(out: str, tmp: Path) -> None:
    lateral = numbers(r"lateral velocity at the hole = NUMBER m/s", out)
    assert len(lateral) == 2 and max(lateral) <= 1e-9, lateral  # CJM and QP
    (difference,) = numbers(r"max \|qd_cjm - qd_qp\| = NUMBER", out)
    assert difference <= 1e-5
    assert "(analytical)" in out and "(qp:daqp)" in out


def check_02(out: str, tmp: Path) -> None:
    rows = {name: numbers(r"NUMBER", rest) for name, rest in
            re.findall(r"^(cjm|qp:daqp)\s+(.*)$", out, flags=re.MULTILINE)}
    assert set(rows) == {"cjm", "qp:daqp"}, out
    for error_max, residual, ee_rms_mm, failed, _step_us in rows.values():
        assert error_max <= 1e-5 and residual <= 1e-8 and ee_rms_mm <= 1.0 and failed == 0
    (difference,) = numbers(r"\|EE RMS error cjm - qp:daqp\| = NUMBER m", out)
    assert difference <= 1e-6
    document = json.loads((tmp / "out" / "metrics.json").read_text())
    assert set(document["controllers"]) == {"cjm", "qp:daqp"}
    assert (tmp / "out" / "constraint_velocity.png").stat().st_size > 0


def check_03(out: str, tmp: Path) -> None:
    distances = numbers(r"min signed distance = NUMBER m", out)
    assert len(distances) == 2 and min(distances) >= -1e-9, distances  # never behind it
    assert numbers(r"failed steps = NUMBER", out) == [0, 0]
    assert max(numbers(r"hole error max = NUMBER m", out)) <= 1e-5


def check_04(out: str, tmp: Path) -> None:
    assert "loaded panda.urdf" in out
    lateral = numbers(r"lateral velocity at the hole = NUMBER m/s", out)
    assert len(lateral) == 3 and max(lateral) <= 1e-9, lateral
    (exact,) = numbers(r"max \|qd_cjm_exact - qd_qp\| = NUMBER", out)
    assert exact <= 1e-6  # undamped CJM = the QP's least-squares optimum


def check_05(out: str, tmp: Path) -> None:
    (deviation,) = numbers(r"deviation max \|qd_mink - qd_cjm\| = NUMBER rad/s", out)
    assert deviation <= 1e-6
    lateral = numbers(r"lateral velocity at the hole = NUMBER m/s", out)
    assert len(lateral) == 2 and max(lateral) <= 1e-9, lateral
    assert "(mink:daqp)" in out


def check_06(out: str, tmp: Path) -> None:
    assert re.search(r"UI on http://127\.0\.0\.1:\d+ ", out), out
    assert numbers(r"target moved NUMBER mm up", out) == [10.0]
    errors = numbers(r"hole error max = NUMBER m", out)
    assert len(errors) == 2 and max(errors) <= 1e-5, errors  # main and ghost


def check_07(out: str, tmp: Path) -> None:
    holes = numbers(r"max hole error = NUMBER m", out)
    tips = numbers(r"max tip error = NUMBER m", out)
    assert len(holes) == len(tips) == 2  # CJM and QP
    assert max(holes) <= 1e-6 and max(tips) <= 1e-3, (holes, tips)
    (difference,) = numbers(r"max \|q_cjm - q_qp\| after 2 s = NUMBER rad", out)
    assert difference <= 5e-3


def check_08(out: str, tmp: Path) -> None:
    (ideal,) = numbers(r"kinematic plant: hole error max NUMBER mm", out)
    (simulated,) = numbers(r"mujoco plant: hole error max NUMBER mm", out)
    (force,) = numbers(r"port force max NUMBER N", out)
    (displacement,) = numbers(r"tissue displacement of NUMBER mm", out)
    assert ideal <= 1e-3 < simulated, (ideal, simulated)  # the body shows, in microns
    assert simulated <= 0.1 and 0.0 < force <= 0.2  # the targets for the CJM
    # the spring's share of the force, 1 N/mm x displacement, is at most the force (the
    # damper adds the rest) and the displacement never exceeds the largest hole error
    assert 1.0 * displacement <= force + 1e-4 and displacement <= simulated + 1e-4


def check_09(out: str, tmp: Path) -> None:
    (pairs,) = numbers(r"NUMBER pairs checked", out)
    (start,) = numbers(r"arms NUMBER mm apart", out)
    (distance,) = numbers(r"pushing: NUMBER mm between", out)
    (trocar,) = numbers(r"trocar error NUMBER um", out)
    assert pairs > 100 and start <= 10.0
    # d_s - 0.5 mm at least (the bound), and no farther than d_s + 0.5 mm: the
    # damper lets the pushed pair close on d_s; each trocar to 1 um
    assert 4.5 <= distance <= 5.5 and trocar <= 1.0, (distance, trocar)
    assert "status least_squares" in out and "held back by collision pair" in out


def check_10(out: str, tmp: Path) -> None:
    assert [numbers(rf"{word} = NUMBER", out) for word in ("cells done", "failed", "skipped")] \
        == [[8], [0], [0]], out
    folder = tmp / "sweep_out"
    assert (folder / "summary.html").stat().st_size > 0
    with sqlite3.connect(folder / "results.sqlite") as connection:
        rows = connection.execute("SELECT controller, status, hole_error_max_m FROM cells").fetchall()
    assert sorted(controller for controller, _, _ in rows) == ["cjm"] * 4 + ["qp:daqp"] * 4
    # the hole error is the encoder noise's (1e-4 rad on each joint, levers under 0.5 m:
    # tens of um, measured 50-61 um); without noise it is 0.3 um (the perfect robot)
    assert all(status == "done" and 1e-6 < error <= 2e-4 for _, status, error in rows), rows
    # paired cells: both controllers hold the same hole against the same noise
    by_controller = {c: sorted(e for c2, _, e in rows if c2 == c) for c in ("cjm", "qp:daqp")}
    assert by_controller["cjm"] == pytest.approx(by_controller["qp:daqp"], rel=1e-3)
    again = subprocess.run([sys.executable, str(EXAMPLES_DIR / "10_sweep.py")], cwd=tmp,
                           capture_output=True, text=True, timeout=TIMEOUT)
    assert "cells done = 0, failed = 0, skipped = 8" in again.stdout, again.stderr


def check_11(out: str, tmp: Path) -> None:
    """What holds however loaded the machine is (the real-time figures: the timing test
    below)."""
    (counts,) = re.findall(r"sent (\d+) commands, received (\d+), applied (\d+), "
                           r"superseded (\d+), dropped (\d+), lost (\d+), hello (\d+)", out)
    sent, received, applied, superseded, dropped, lost, hello = (int(n) for n in counts)
    assert sent == received == 5001 and dropped == lost == 0, out
    # the first commands, sent before the master heard the launch, are hellos: answered
    assert applied + superseded + hello == received and hello >= 1, out
    (feedback,) = numbers(r"feedback received: NUMBER", out)
    assert feedback == sent
    (hole,) = numbers(r"hole error max NUMBER um", out)
    ((silent, timeout),) = re.findall(r"silent for NUMBER ms \(timeout NUMBER ms\)".replace(
        "NUMBER", NUMBER), out)
    # every step ok by the supervisor's measure; the watchdog released the master only
    # after its timeout of silence
    assert hole <= 1e6 * SupervisorConfig().tolerance and float(silent) >= float(timeout), out


CHECKS = {"01_cjm_vs_qp.py": check_01, "02_closed_loop.py": check_02, "03_barrier.py": check_03,
          "04_any_urdf.py": check_04, "05_mink_peer.py": check_05,
          "06_embed_teleop_app.py": check_06, "07_two_trocars.py": check_07,
          "08_physics_plant.py": check_08, "09_collision_avoidance.py": check_09,
          "10_sweep.py": check_10, "11_network_master.py": check_11}


def test_the_examples_folder_has_the_documented_scripts():
    names = [path.name for path in EXAMPLES]
    assert set(CHECKS) <= set(names)
    readme = (EXAMPLES_DIR / "README.md").read_text(encoding="utf-8")
    assert all(name in readme for name in names), "examples/README.md must list every script"


def run(script: Path, tmp_path: Path) -> str:
    """What ``script`` printed, run headless in ``tmp_path``; it must succeed."""
    arguments = [a.format(tmp=tmp_path) for a in ARGUMENTS.get(script.name, [])]
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONUNBUFFERED="1")
    result = subprocess.run([sys.executable, str(script), *arguments], cwd=tmp_path, env=env,
                            capture_output=True, text=True, timeout=TIMEOUT)
    assert result.returncode == 0, f"{script.name} failed:\n{result.stdout}\n{result.stderr}"
    assert result.stdout.strip(), f"{script.name} printed nothing"
    return result.stdout


@pytest.mark.parametrize("script", EXAMPLES, ids=[path.name for path in EXAMPLES])
def test_example_runs_and_prints_its_numbers(script: Path, tmp_path: Path):
    out = run(script, tmp_path)
    check = CHECKS.get(script.name)
    if check is not None:
        check(out, tmp_path)


@pytest.mark.timing
def test_the_network_master_example_meets_its_real_time_bounds(tmp_path: Path):
    """The issue's bounds, which need the 1 kHz loop to keep its rate: the EE tracks the
    circle to 1 mm RMS with the hole to 1 um, and stops 100-150 ms after the master's last
    command (the script's clock starts after its last period's sleep)."""
    out = run(EXAMPLES_DIR / "11_network_master.py", tmp_path)
    (rms,) = numbers(r"tracking error RMS NUMBER mm", out)
    (hole,) = numbers(r"hole error max NUMBER um", out)
    (stopped,) = numbers(r"robot stopped NUMBER ms later", out)
    assert rms <= 1.0 and hole <= 1.0 and 100.0 <= stopped <= 150.0, out


def test_the_network_master_example_drives_a_running_page(tmp_path: Path, monkeypatch):
    """``--drive PORT --key KEY``: the example streams its circles to a running session's
    UDP input (the app ``teleop web`` serves, its control thread running, a master
    attached with a key drawn as ``teleop web`` draws one): every datagram it sends is
    received or counted lost, and the page's target follows the circle, 2 s of a 5 s
    circle of 1 cm: the chord between the first sample the control tick applied (after
    the hellos sent before the launch was heard, never applied) and the last, at most
    2 sin(72 deg) cm. What the tick applied, not the wall clock, sets the chord: on a
    loaded machine the first ticks after the launch take a later sample."""
    import threading
    import time

    from teleop import load_robot
    from teleop.inputs import UdpMaster
    from web.app import ControlThread, TeleopApp
    from web.app.devices import INPUT_TIMEOUT_RANGE

    app = TeleopApp(load_robot("sda10f"), record_dir=tmp_path, scene_dir=tmp_path / "scenes")
    master = UdpMaster(port=0)
    app.devices.attach(master)
    # the watchdog is not under test: the longest timeout, so a stalled sender on a loaded
    # machine does not release the target to where the robot lags
    app.devices.set_input_timeout(INPUT_TIMEOUT_RANGE[1])
    applied: list[int] = []  # the sequence of each sample the control tick applied
    record_use = master.used

    def used(sample, command_time: float) -> None:
        applied.append(sample.sequence)
        record_use(sample, command_time)

    monkeypatch.setattr(master, "used", used)
    control = ControlThread(app)
    control.start()
    start = app.console.target.translation.copy()
    farthest = [0.0]
    done = threading.Event()

    def watch() -> None:  # the target's farthest from where it started
        while not done.is_set():
            farthest[0] = max(farthest[0], float(np.linalg.norm(app.console.target.translation - start)))
            time.sleep(0.002)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    try:
        script = EXAMPLES_DIR / "11_network_master.py"
        result = subprocess.run([sys.executable, str(script), "--drive", str(master.port),
                                 "--key", master.key.hex(), "--seconds", "2"], cwd=tmp_path,
                                capture_output=True, text=True, timeout=TIMEOUT)
        # the tick that applies the last sample: sequence 2001 (2 s at 1 kHz, and k = 0)
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline and not (applied and applied[-1] >= 2001):
            time.sleep(0.01)
    finally:
        done.set()
        watcher.join(2.0)
        control.stop()
        farthest[0] = max(farthest[0], float(np.linalg.norm(app.console.target.translation - start)))
        stats = master.statistics()
        app.devices.close()
    assert result.returncode == 0, result.stderr
    (sent,) = numbers(r"sent NUMBER commands to 127\.0\.0\.1", result.stdout)
    assert sent == 2001 and stats["received"] + stats.get("lost", 0) == sent, (result.stdout, stats)
    assert stats["received"] >= 0.9 * sent and stats.get("unauthenticated", 0) == 0, stats
    assert stats.get("releases", 0) == 0, stats
    # the commands sent before the launch was heard are hellos (answered, never applied,
    # protocol v3); sample k of the 1 kHz stream is sequence k + 1, at 2 pi k / 5000 rad on
    # the 1 cm circle: the target moves by the chord from the first applied to the last
    hellos = stats.get("hello", 0)
    first, last = applied[0], applied[-1]
    assert first > hellos and last == sent, (applied[:3], applied[-3:], hellos)
    chord = 0.02 * np.sin(np.pi * (last - first) / 5000.0)
    assert chord - 0.5e-3 <= farthest[0] <= chord + 1e-4, (farthest[0], chord, first, hellos)
    # a key that is not one: one line, exit code 2 (argparse), no traceback
    bad = subprocess.run([sys.executable, str(script), "--drive", str(master.port), "--key",
                          "not-hex"], cwd=tmp_path, capture_output=True, text=True,
                         timeout=TIMEOUT)
    assert bad.returncode == 2 and "hexadecimal" in bad.stderr and "Traceback" not in bad.stderr
