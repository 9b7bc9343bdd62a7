"""``teleop sweep``: the grid and its keys, the results database, the engines (a local
pool, Ray), interrupt and resume, bad specs (docs/sweep.md)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import textwrap
import threading
import time
from pathlib import Path

import pytest
from browser_helpers import answer_ctrl_c
from hypothesis import given, settings
from hypothesis import strategies as st

from teleop.cli.main import main
from teleop.experiments.sweep import (Cell, ResultsDatabase, build_spec, compare_command,
                                      load_spec, run_cell, run_sweep)
from teleop.experiments.sweep.cell import DONE, FAILED
from teleop.experiments.sweep.database import DATABASE_NAME
from teleop.experiments.sweep.pool import LocalPool
from teleop.experiments.sweep.spec import cell_key

REPO = Path(__file__).resolve().parents[1]


def deterministic(metrics: dict) -> dict:
    """The metrics a rerun must reproduce exactly: all but the timings."""
    return {name: value for name, value in metrics.items() if "time" not in name}


def rows_by_key(folder: Path) -> dict:
    with ResultsDatabase(folder / DATABASE_NAME) as database:
        return {row.key: row for row in database.rows()}


# --- the grid ---------------------------------------------------------------------------

@settings(max_examples=40, deadline=None)
@given(kps=st.lists(st.sampled_from([5.0, 10.0, 20.0, 40.0]), min_size=1, max_size=3, unique=True),
       noises=st.lists(st.sampled_from([0.0, 1e-5, 1e-4]), min_size=1, max_size=3, unique=True),
       seeds=st.integers(1, 4),
       controllers=st.lists(st.sampled_from(["cjm", "qp:daqp", "cjm:general"]), min_size=1,
                            max_size=3, unique=True))
def test_a_grid_expands_to_every_combination_once_each_with_its_own_key(kps, noises, seeds,
                                                                          controllers):
    spec = build_spec({"scenarios": ["paper-hole"], "controllers": controllers,
                       "seeds": seeds, "kp": kps, "imperfections": {"encoder_noise": noises}})
    cells = spec.cells()
    assert len(cells) == spec.size == len(kps) * len(noises) * seeds * len(controllers)
    combinations = {(c["kp"], c["encoder_noise"], c["seed"], c["controller"]) for c in cells}
    assert combinations == {(k, n, s, c) for k in kps for n in noises for s in range(seeds)
                            for c in controllers}
    assert len({c.key for c in cells}) == len(cells)
    for cell in cells:  # the key is the inputs', whatever the order they were given in
        assert Cell.of(dict(reversed(list(cell.inputs.items())))).key == cell.key
        assert cell.key == cell_key(cell.inputs)


def test_a_field_at_its_default_changes_no_key_and_one_is_one_point_zero():
    base = Cell.of({"scenario": "paper-hole", "controller": "cjm"})
    assert Cell.of({"scenario": "paper-hole", "controller": "cjm", "kp": 20,
                    "seed": 0, "encoder_noise": 0}).key == base.key
    assert Cell.of({"scenario": "paper-hole", "controller": "cjm", "kp": 10}).key == \
        Cell.of({"scenario": "paper-hole", "controller": "cjm", "kp": 10.0}).key
    assert Cell.of({"scenario": "paper-hole", "controller": "cjm", "seed": 1}).key != base.key


def test_a_spec_file_and_the_same_flags_give_the_same_cells(tmp_path):
    path = tmp_path / "spec.toml"
    path.write_text(textwrap.dedent("""
        scenarios = ["paper-hole", "trocar-circle"]
        controllers = ["cjm", "qp:daqp"]
        seeds = [3, 7]
        duration = 0.5
        kp = [10, 20]
        [imperfections]
        encoder_noise = 1e-4
        calibration_error_mm = 1.0
        [variations]
        trocar_shift = 0.01
    """))
    from_file = load_spec(path)
    same = build_spec({"scenarios": ["paper-hole", "trocar-circle"],
                       "controllers": ["cjm", "qp:daqp"], "seeds": [3, 7], "duration": 0.5,
                       "kp": [10.0, 20.0], "encoder_noise": 1e-4, "calibration_error_mm": 1,
                       "trocar_shift": 0.01})
    assert [c.key for c in from_file.cells()] == [c.key for c in same.cells()]
    assert len(from_file.cells()) == 16
    json_path = tmp_path / "spec.json"
    json_path.write_text(json.dumps({"scenarios": ["paper-hole"], "controllers": ["cjm"]}))
    assert load_spec(json_path, {"seeds": 2}).size == 2  # a flag over the file's fields


BAD_SPECS = [
    ({"scenarios": ["paper-hole"], "controllers": ["nope"]}, "controllers"),
    ({"scenarios": ["nowhere"], "controllers": ["cjm"]}, "scenarios"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"],
      "imperfections": {"encoder_noise": -1e-3}}, "encoder_noise"),
    ({"scenarios": [], "controllers": ["cjm"]}, "scenarios is empty"),
    ({"controllers": ["cjm"]}, "scenarios is required"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "colour": 1}, "'colour'"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "imperfections": [1]},
     "imperfections must be a table"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "seeds": [2**64]}, "seeds"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "kp": [20, 20.0]}, "kp lists"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "payload": 0.5}, "payload"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "duration": 0}, "duration"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "seeds": 0}, "seeds"),
    ({"scenarios": [3], "controllers": ["cjm"]}, "scenarios"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "time_limit": -1}, "time_limit"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "plants": ["kinematic", "mujoco"],
      "imperfections": {"calibration_error_mm": 1.0}}, "calibration error needs"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "constraint_gain": [5.0, 5000.0]},
     "constraint_gain"),
    ({"scenarios": ["paper-hole"], "controllers": ["cjm"], "rate": 1e-9}, "control periods"),
]


@pytest.mark.parametrize("document, named", BAD_SPECS)
def test_a_bad_spec_is_one_line_naming_the_field_and_exit_2(document, named, tmp_path, capsys):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(document))
    assert main(["sweep", "--spec", str(path), "--out", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("teleop sweep: ")
    assert named in error and str(path) in error
    assert not (tmp_path / "out" / DATABASE_NAME).exists()


@pytest.mark.parametrize("content, named", [("scenarios = [", "not a TOML spec"),
                                            ("\x00\x01", "not a TOML spec")])
def test_a_file_that_is_not_a_spec_is_one_line_and_exit_2(content, named, tmp_path, capsys):
    path = tmp_path / "spec.toml"
    path.write_text(content)
    assert main(["sweep", "--spec", str(path), "--out", str(tmp_path / "o")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and named in error


@pytest.mark.parametrize("args, named", [
    (["--address", "127.0.0.1:1"], "--address needs --engine ray"),
    (["--engine", "ray", "--address", "127.0.0.1:1"], "cannot reach the Ray cluster"),
    (["--engine", "ray", "--address", "nowhere"], "HOST:PORT"),
    (["--workers", "0"], "workers must be >= 1"),
    (["--retries", "-1"], "retries must be >= 0"),
    (["--seeds", "a"], "--seeds"),
])
def test_bad_engine_options_are_one_line_and_exit_2(args, named, tmp_path, capsys):
    code = None
    try:
        code = main(["sweep", "--scenarios", "paper-hole", "--controllers", "cjm",
                     "--duration", "0.1", "--out", str(tmp_path / "o"), *args])
    except SystemExit as exit_:  # argparse's own errors
        code = exit_.code
    assert code == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and named in error


def test_a_folder_that_cannot_be_made_and_a_foreign_database_are_refused(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    common = ["sweep", "--scenarios", "paper-hole", "--controllers", "cjm", "--duration", "0.1"]
    assert main([*common, "--out", str(blocker / "sub")]) == 2
    assert "cannot make the sweep folder" in capsys.readouterr().err
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    with sqlite3.connect(foreign / DATABASE_NAME) as connection:
        connection.execute("CREATE TABLE notes (text TEXT)")
        connection.execute("INSERT INTO notes VALUES ('mine')")
    assert main([*common, "--out", str(foreign)]) == 2
    assert "another program" in capsys.readouterr().err
    with sqlite3.connect(foreign / DATABASE_NAME) as connection:  # untouched
        assert connection.execute("SELECT text FROM notes").fetchall() == [("mine",)]


# --- one cell ---------------------------------------------------------------------------

def test_a_cell_is_its_compare_command(tmp_path):
    """A cell's metrics and those of the ``teleop compare`` command ``show`` prints are
    equal, with every kind of input on."""
    cell = Cell.of({"scenario": "paper-hole", "controller": "cjm", "seed": 4, "duration": 0.5,
                    "encoder_noise": 1e-4, "latency": 2, "kp": 15, "constraint_gain": 5.0,
                    "trocar_shift": 0.01, "path_amplitude": 0.005,
                    "calibration_error_mm": 0.5, "calibration_error_mrad": 1.0})
    outcome = run_cell(cell.inputs, time_limit=300)
    assert outcome["status"] == DONE, outcome["reason"]
    command = compare_command(cell.inputs, out=str(tmp_path / "compare"))
    words = command.split()
    assert words[:2] == ["teleop", "compare"]
    assert main([*words[1:], "--no-plots", "--quiet"]) == 0
    document = json.loads((tmp_path / "compare" / "metrics.json").read_text())
    assert deterministic(document["controllers"]["cjm"]) == deterministic(outcome["metrics"])
    assert outcome["metrics"]["hole_error_max_m"] > 0  # the calibration error is felt


def test_a_cell_stops_itself_at_its_time_limit():
    outcome = run_cell({"scenario": "paper-hole", "controller": "cjm:python"}, time_limit=0.05)
    assert outcome["status"] == FAILED and outcome["metrics"] is None
    assert outcome["reason"].startswith("time limit 0.05 s exceeded at t=")
    assert outcome["reason"].endswith("s of 10 s")
    assert outcome["elapsed_s"] < 10  # stopped long before its 10 s of simulation


def test_a_cells_own_error_is_its_failed_outcome():
    outcome = run_cell({"scenario": "paper-hole", "controller": "cjm", "plant": "mujoco",
                        "calibration_error_mm": 1.0}, time_limit=60)
    assert outcome["status"] == FAILED
    assert "calibration" in outcome["reason"]


# --- the database -----------------------------------------------------------------------

WRITER = textwrap.dedent("""
    import sys
    from teleop.experiments.sweep import Cell, ResultsDatabase
    database = ResultsDatabase(sys.argv[1])
    for i in range(100000):
        cell = Cell.of({"scenario": "paper-hole", "controller": "cjm", "seed": i})
        outcome = {"status": "done", "reason": None, "elapsed_s": 1.0, "worker": "w",
                   "version": "v", "metrics": {"hole_error_max_m": i * 1e-6,
                                               "padding": [float(i)] * 2000}}
        database.write(cell.key, cell.inputs, outcome, 1)
        if i == 0:
            print("first", flush=True)
""")


@pytest.mark.parametrize("delay", [0.0, 0.05, 0.2, 0.37, 0.8])
def test_the_database_stays_readable_after_a_kill_during_writes(delay, tmp_path):
    path = tmp_path / DATABASE_NAME
    writer = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdout=subprocess.PIPE,
                              text=True)
    assert writer.stdout.readline().strip() == "first"
    time.sleep(delay)
    writer.kill()
    writer.wait(timeout=30)
    with sqlite3.connect(path) as connection:
        assert connection.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    with ResultsDatabase(path) as database:
        rows = database.rows()
    assert rows, "the first row was committed before the writer said so"
    seeds = sorted(row.inputs.get("seed", 0) for row in rows)
    assert seeds == list(range(len(rows)))  # the rows are a prefix of the writes
    for row in rows:
        assert row.key == cell_key(row.inputs)
        seed = row.inputs.get("seed", 0)
        assert row.metrics["padding"] == [float(seed)] * 2000
        assert row.metrics["hole_error_max_m"] == seed * 1e-6


def test_a_cell_is_never_written_twice(tmp_path):
    cell = Cell.of({"scenario": "paper-hole", "controller": "cjm"})
    outcome = {"status": DONE, "metrics": {"failed_steps": 0}, "elapsed_s": 1.0}
    with ResultsDatabase(tmp_path / DATABASE_NAME) as first, \
            ResultsDatabase(tmp_path / DATABASE_NAME) as second:
        assert first.write(cell.key, cell.inputs, outcome, 1)
        assert not second.write(cell.key, cell.inputs, {**outcome, "elapsed_s": 2.0}, 1)
        (row,) = second.rows()
    assert row.elapsed_s == 1.0


# --- the engines ------------------------------------------------------------------------

SMALL = {"scenarios": ["paper-hole", "trocar-circle"], "controllers": ["cjm", "qp:daqp"],
         "seeds": 2, "duration": 0.3, "imperfections": {"encoder_noise": 1e-4}}


def test_the_pool_runs_every_cell_once_as_a_cell_alone_would(tmp_path):
    spec = build_spec(SMALL)
    run = run_sweep(spec, tmp_path, workers=2, progress=False)
    assert (run.done, run.failed, run.skipped) == (8, 0, 0)
    rows = rows_by_key(tmp_path)
    assert set(rows) == {cell.key for cell in spec.cells()}
    alone = spec.cells()[5]
    outcome = run_cell(alone.inputs, time_limit=300)
    assert deterministic(rows[alone.key].metrics) == deterministic(outcome["metrics"])
    again = run_sweep(spec, tmp_path, workers=2, progress=False)
    assert (again.ran, again.skipped) == (0, 8)


def test_a_pool_worker_killed_in_its_cell_is_replaced_and_the_cell_runs_again(tmp_path):
    spec = build_spec({**SMALL, "seeds": 1})
    pool = LocalPool(workers=2, retries=2)
    killed = []

    def kill_first(cell):
        if not killed:
            pid = pool.running()[cell.key]
            os.kill(pid, signal.SIGKILL)
            killed.append((cell.key, pid))

    finished = {f.cell.key: f for f in pool.run(spec.cells(), time_limit=300,
                                                 on_start=kill_first)}
    assert set(finished) == {cell.key for cell in spec.cells()}
    assert all(f.outcome["status"] == DONE for f in finished.values())
    key, pid = killed[0]
    assert finished[key].attempts == 2
    assert all(f.attempts == 1 for k, f in finished.items() if k != key)


def test_a_pool_worker_that_dies_between_cells_is_replaced(tmp_path):
    cells = build_spec({**SMALL, "seeds": 1, "controllers": ["cjm"]}).cells()
    pool = LocalPool(workers=1, retries=0)
    finished = []
    for end in pool.run(cells, time_limit=300):
        finished.append(end)
        if len(finished) == 1:  # the worker is idle now: kill it before its next cell
            (worker,) = pool._pool
            worker.process.kill()
            worker.process.join(timeout=30)
    assert [f.outcome["status"] for f in finished] == [DONE, DONE]
    assert [f.attempts for f in finished] == [1, 1]  # a dead idle worker costs no attempt


def test_retry_failed_runs_only_the_failed_cells_again(tmp_path):
    spec = build_spec({"scenarios": ["paper-hole"], "controllers": ["cjm", "cjm:python"],
                       "duration": 0.3, "time_limit": 0.01})
    first = run_sweep(spec, tmp_path, workers=1, progress=False)
    assert first.failed >= 1  # cjm:python cannot run 300 steps in 10 ms
    failed = {k for k, row in rows_by_key(tmp_path).items() if row.status == FAILED}
    done = {k: row for k, row in rows_by_key(tmp_path).items() if row.status == DONE}
    again = run_sweep(build_spec({**{"scenarios": ["paper-hole"],
                                     "controllers": ["cjm", "cjm:python"]},
                                  "duration": 0.3, "time_limit": 300}),
                      tmp_path, workers=1, retry_failed=True, progress=False)
    assert (again.ran, again.skipped) == (len(failed), len(done))
    after = rows_by_key(tmp_path)
    assert all(after[k].status == DONE for k in failed)
    assert all(after[k] == row for k, row in done.items())


def test_a_stuck_worker_is_killed_past_the_limit_and_the_sweep_goes_on(tmp_path):
    cells = build_spec({**SMALL, "seeds": 1, "controllers": ["cjm"]}).cells()
    pool = LocalPool(workers=1, retries=0, grace=1.0)
    stopped = []

    def stop_first(cell):
        if not stopped:
            os.kill(pool.running()[cell.key], signal.SIGSTOP)
            stopped.append(cell.key)

    # the limit is the stopped cell's wait; the others need it too, on a loaded machine, and
    # a fresh worker's imports count in it (2 s with load 8 killed the cell after the stop)
    finished = {f.cell.key: f for f in pool.run(cells, time_limit=15.0, on_start=stop_first)}
    assert finished[stopped[0]].outcome["status"] == FAILED
    assert "its worker was killed" in finished[stopped[0]].outcome["reason"]
    others = [f for k, f in finished.items() if k != stopped[0]]
    assert others and all(f.outcome["status"] == DONE for f in others)


def test_interrupt_and_resume_run_no_cell_twice_and_lose_none(tmp_path):
    out = tmp_path / "sweep"
    command = [sys.executable, "-m", "teleop", "sweep", "--scenarios", "paper-hole,trocar-circle",
               "--controllers", "cjm,qp:daqp,cjm:general", "--seeds", "2", "--duration", "0.5",
               "--encoder-noise", "1e-5", "--workers", "2", "--reports", "0", "--out", str(out)]
    first = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             start_new_session=True,
                             preexec_fn=answer_ctrl_c)
    deadline = time.monotonic() + 600
    while time.monotonic() < deadline and first.poll() is None:
        if (out / DATABASE_NAME).exists() and len(_keys(out)) >= 4:
            break
        time.sleep(0.2)
    assert first.poll() is None, first.communicate()
    os.killpg(first.pid, signal.SIGINT)
    _, error = first.communicate(timeout=120)
    assert first.returncode == 130, error
    assert "the same command resumes" in error
    before = rows_by_key(out)
    assert 4 <= len(before) < 12
    second = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stderr
    assert f"skipped {len(before)} cells" in second.stdout
    after = rows_by_key(out)
    assert len(after) == 12
    for key, row in before.items():
        assert after[key] == row  # untouched: not run again


def test_an_interrupted_sweep_returns_130_to_a_caller_and_ends_only_the_program(tmp_path,
                                                                                capsys):
    """``main`` given its arguments (a caller in its own process, as here) returns 130
    from a stopped sweep, its database closed; the program itself (``python -m teleop``,
    the subprocess tests above and below) ends at once instead (``end_process``). SIGTERM
    here, as Ctrl-C, since a test run in the background ignores SIGINT."""
    out = tmp_path / "sweep"
    stop = threading.Event()

    def terminate_after_the_first_cell() -> None:
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and not stop.is_set():
            if (out / DATABASE_NAME).exists() and _keys(out):
                os.kill(os.getpid(), signal.SIGTERM)
                return
            time.sleep(0.1)

    sender = threading.Thread(target=terminate_after_the_first_cell)
    sender.start()
    try:
        code = main(["sweep", "--scenarios", "paper-hole", "--controllers", "cjm,qp:daqp",
                     "--seeds", "10", "--duration", "2.0", "--workers", "2", "--reports", "0",
                     "--quiet", "--out", str(out)])
    finally:
        stop.set()
        sender.join()
    error = capsys.readouterr().err
    assert code == 130, error
    assert "the same command resumes" in error and "stopped (SIGTERM)" in error
    assert 1 <= len(rows_by_key(out)) < 20  # closed: readable, the cells written kept


def test_a_worker_past_its_deadline_is_ended_even_holding_the_interpreter():
    """:func:`ended_past`: a process stuck in one C call that holds the interpreter (no
    Python handler could run) is ended by the kernel at the deadline, SIGALRM its end; a
    block that ends in time leaves no timer and the handler it found."""
    stuck = subprocess.run([sys.executable, "-c", textwrap.dedent("""
        from teleop.experiments.sweep.worker_deadline import ended_past
        with ended_past(0.5) as armed:
            assert armed
            sum(range(10**13))  # hours in one C call
        """)], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert stuck.returncode == -signal.SIGALRM, stuck.stderr
    in_time = subprocess.run([sys.executable, "-c", textwrap.dedent("""
        import signal, time
        from teleop.experiments.sweep.worker_deadline import ended_past
        def mine(signum, frame):
            raise SystemExit("my handler ran")
        signal.signal(signal.SIGALRM, mine)
        with ended_past(0.3):
            pass
        assert signal.getsignal(signal.SIGALRM) is mine
        assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)
        time.sleep(0.6)
        print("alive")
        """)], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert in_time.returncode == 0 and in_time.stdout.strip() == "alive", in_time.stderr


def _keys(folder: Path) -> set[str]:
    with ResultsDatabase(folder / DATABASE_NAME) as database:
        return database.keys()


@pytest.fixture(scope="module")
def ray_instance(tmp_path_factory):
    """A local Ray instance started as a sweep starts one: 2 CPUs, no dashboard, on
    loopback, its files under the test's folder (Ray is in the test extra)."""
    from teleop.experiments.sweep.ray_engine import RayEngine

    engine = RayEngine(workers=2, out=tmp_path_factory.mktemp("ray"))
    engine.connect()
    yield
    engine.shutdown()


def test_ray_and_the_pool_give_identical_metrics_cell_by_cell(tmp_path, ray_instance):
    spec = build_spec(SMALL)
    run_sweep(spec, tmp_path / "pool", workers=2, progress=False)
    run = run_sweep(spec, tmp_path / "ray", engine="ray", workers=2, progress=False)
    assert (run.done, run.failed) == (8, 0)
    pool, on_ray = rows_by_key(tmp_path / "pool"), rows_by_key(tmp_path / "ray")
    assert set(pool) == set(on_ray) == {c.key for c in spec.cells()}
    for key in pool:
        assert deterministic(pool[key].metrics) == deterministic(on_ray[key].metrics), key


def ray_task_pids(title: str = "ray::run_cell_task") -> list[int]:
    """The processes whose title is ``title`` (Ray names a worker after its task)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:  # ended meanwhile
                continue
            if title in cmdline:
                pids.append(int(entry.name))
    return pids


def test_a_ray_worker_killed_mid_sweep_loses_no_cell(tmp_path, ray_instance):
    spec = build_spec({**SMALL, "duration": 1.0})
    killed = []

    def kill_a_worker(cell):
        if killed:
            return
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not killed:
            for pid in ray_task_pids()[:1]:
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
            time.sleep(0.05)

    from teleop.experiments.sweep.ray_engine import RayEngine

    engine = RayEngine(workers=2, retries=3)
    finished = [f for f in engine.run(spec.cells(), 300, on_start=kill_a_worker)]
    assert killed, "no Ray worker was found running a cell"
    keys = [f.cell.key for f in finished]
    assert sorted(keys) == sorted(c.key for c in spec.cells())  # every cell once
    assert all(f.outcome["status"] == DONE for f in finished)


def test_a_ray_cell_past_its_deadline_ends_its_worker_and_the_instance_goes_on(ray_instance):
    """A task still running ``grace`` past its cell's time limit ends its own worker
    (:mod:`teleop.experiments.sweep.worker_deadline`; its deadline here 2 ms after it
    starts, inside the cell's setup): the cell failed saying so, at its first attempt (not
    run again, as the pool does with a stuck cell), no task cancelled; then the same
    instance runs cells to the end."""
    from teleop.experiments.sweep.ray_engine import RayEngine

    cells = build_spec({**SMALL, "seeds": 1, "controllers": ["cjm"]}).cells()
    engine = RayEngine(workers=2, retries=2, grace=1e-3)
    stuck = list(engine.run(cells, time_limit=1e-3))
    assert sorted(f.cell.key for f in stuck) == sorted(c.key for c in cells)
    for finished in stuck:
        assert finished.outcome["status"] == FAILED and finished.attempts == 1
        assert "its worker ended itself" in finished.outcome["reason"], finished.outcome
    again = list(RayEngine(workers=2, retries=2).run(cells, time_limit=300))
    assert [f.outcome["status"] for f in again] == [DONE] * len(cells)


def test_a_local_ray_instance_writes_only_under_the_sweep_folder(tmp_path):
    """Ray's session files (sockets, logs) under ``OUT/ray``, its token in memory: nothing
    in the home folder (Ray's ``~/.ray/auth_token``) or the temporary folder (``/tmp/ray``).
    A fresh process: the module's instance would be reused."""
    home, scratch = tmp_path / "home", tmp_path / "tmp"
    home.mkdir()
    scratch.mkdir()
    out = Path(tempfile.mkdtemp(prefix="ts-", dir="/tmp")) / "out"  # short: a socket path
    try:
        script = textwrap.dedent(f"""
            from teleop.experiments.sweep import build_spec, run_sweep
            if __name__ == "__main__":
                spec = build_spec({{"scenarios": ["paper-hole"], "controllers": ["cjm"],
                                   "seeds": 1, "duration": 0.2}})
                run = run_sweep(spec, {str(out)!r}, engine="ray", workers=1, progress=False)
                assert (run.done, run.failed) == (1, 0), run
        """)
        environment = {**os.environ, "HOME": str(home), "TMPDIR": str(scratch)}
        environment.pop("RAY_AUTH_MODE", None)
        environment.pop("RAY_ADDRESS", None)
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              timeout=300, env=environment, cwd=REPO)
        assert done.returncode == 0, done.stderr[-3000:]
        assert list(home.rglob("*")) == []
        assert list(scratch.rglob("*")) == []
        sessions = list((out / "ray").glob("session_*"))
        assert sessions and any((out / "ray").rglob("*.log")), list((out / "ray").rglob("*"))
    finally:
        shutil.rmtree(out.parent, ignore_errors=True)


def test_ctrl_c_stops_a_ray_sweep_and_every_process_of_its_instance(tmp_path):
    """SIGINT to the sweep's process group (Ctrl-C) with cells in flight on a local Ray
    instance: exit 130 and the resume note, and no process naming the instance's session
    folder (under the sweep's: its GCS, raylet, monitor and agents) left running."""
    out = Path(tempfile.mkdtemp(prefix="tc-", dir="/tmp")) / "out"  # short: a socket path
    command = [sys.executable, "-m", "teleop", "sweep", "--scenarios", "paper-hole,trocar-circle",
               "--controllers", "cjm,qp:daqp,cjm:general", "--seeds", "2", "--duration", "1.0",
               "--encoder-noise", "1e-5", "--workers", "2", "--reports", "0",
               "--engine", "ray", "--out", str(out)]
    try:
        sweep = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 text=True, start_new_session=True, cwd=REPO,
                                 preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and sweep.poll() is None:
            if (out / DATABASE_NAME).exists() and len(_keys(out)) >= 2:
                break
            time.sleep(0.2)
        assert sweep.poll() is None, sweep.communicate()
        assert ray_task_pids(str(out / "ray")), "no process of the Ray instance was found"
        os.killpg(sweep.pid, signal.SIGINT)
        _, error = sweep.communicate(timeout=120)
        assert sweep.returncode == 130, error
        assert "the same command resumes" in error
        assert ray_task_pids(str(out / "ray")) == []
    finally:
        shutil.rmtree(out.parent, ignore_errors=True)


def test_a_sweep_folder_too_long_for_a_socket_gives_ray_a_temporary_folder(tmp_path):
    from teleop.experiments.sweep.ray_engine import LONGEST_RAY_FOLDER, ray_folder

    short = Path("/tmp/s")
    assert ray_folder(short) == (short / "ray", False)
    deep = tmp_path / ("x" * LONGEST_RAY_FOLDER)
    folder, temporary = ray_folder(deep)
    try:
        assert temporary and folder.is_dir() and not folder.is_relative_to(deep)
        assert len(os.fsencode(folder)) <= LONGEST_RAY_FOLDER
    finally:
        folder.rmdir()


def _children(pid: int) -> set[int]:
    """The processes ``pid`` started (Linux's ``/proc/PID/task/*/children``)."""
    found: set[int] = set()
    for task in Path(f"/proc/{pid}/task").iterdir():
        found |= {int(c) for c in (task / "children").read_text().split()}
    return found


def _cpu_s(pid: int) -> float:
    """CPU time process ``pid`` has used (s; user and system)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie has ended; its parent (gone) did not reap it


def test_pool_workers_die_with_a_driver_killed_by_sigkill(tmp_path):
    """A driver killed with SIGKILL (no ``finally`` runs) leaves no worker running its cell
    (Linux's parent-death signal; the test reads /proc, as the CI machine has)."""
    command = [sys.executable, "-m", "teleop", "sweep", "--scenarios", "paper-hole",
               "--controllers", "cjm,qp:daqp", "--seeds", "2", "--duration", "600",
               "--workers", "2", "--reports", "0", "--out", str(tmp_path / "sweep")]
    driver = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        workers: set[int] = set()
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and (len(workers) < 2 or min(map(_cpu_s, workers)) < 4):
            workers = {pid for pid in _children(driver.pid)
                       if b"spawn_main" in Path(f"/proc/{pid}/cmdline").read_bytes()}
            time.sleep(0.1)
        # each worker in its cell: 4 s of CPU time, past its imports (0.7 s)
        assert len(workers) == 2 and min(map(_cpu_s, workers)) >= 4, "no two workers in cells"
        driver.kill()
        driver.wait(timeout=30)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and any(_alive(pid) for pid in workers):
            time.sleep(0.05)
        assert not any(_alive(pid) for pid in workers), "a worker outlived its driver"
    finally:
        driver.kill()
