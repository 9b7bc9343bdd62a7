"""Ctrl-C to exit of ``teleop sweep`` (issue 33 item 4, docs/sweep.md "Interrupted"): the
local pool and a local Ray instance, at idle and beside CPU hogs.

Each run starts ``python -m teleop sweep`` in a session of its own (SIGINT at its default,
as a terminal's Ctrl-C finds it), waits until the sweep's database holds a written cell
and every worker is in its next one (``--settle`` s more), sends SIGINT to the sweep's
process group (what Ctrl-C does) and times the wait until the process has ended: the
figure is the time from the signal to the exit, each run's exit code beside it (130 is
the interrupted sweep's). With ``--hogs N``, N processes running ``while 1: pass`` share
the cores for the whole measurement (each engine's runs, the sweep's start included).

Run:  OPENBLAS_NUM_THREADS=1 python docs/measure_sweep_interrupt.py [--engines local,ray]
      [--runs 5] [--hogs 0,3] [--workers 2] [--settle 0.5]
(a loaded machine moves these figures: the load average is printed beside each set)
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: a cell of a few seconds, enough of them that cells are always in flight
SWEEP = ["sweep", "--scenarios", "paper-hole,trocar-circle", "--controllers", "cjm,qp:daqp",
         "--seeds", "20", "--duration", "2.0", "--encoder-noise", "1e-5", "--reports", "0",
         "--quiet"]


def written_cells(database: Path) -> int:
    """The rows of the sweep's results database (0 while it is not there)."""
    if not database.exists():
        return 0
    try:
        with sqlite3.connect(f"file:{database}?mode=ro", uri=True, timeout=1.0) as connection:
            return int(connection.execute("SELECT COUNT(*) FROM cells").fetchone()[0])
    except sqlite3.Error:  # being made
        return 0


def interrupt_once(engine: str, workers: int, settle: float) -> tuple[float, int, str]:
    """One sweep interrupted with a written cell behind it: seconds from SIGINT to its
    exit, its exit code and the last line it wrote to stderr."""
    scratch = Path(tempfile.mkdtemp(prefix="si-", dir="/tmp"))  # short: Ray's socket paths
    out = scratch / "out"
    command = [sys.executable, "-m", "teleop", *SWEEP, "--engine", engine,
               "--workers", str(workers), "--out", str(out)]
    environment = {**os.environ, "PYTHONPATH": str(ROOT)}
    try:
        sweep = subprocess.Popen(command, cwd=ROOT, env=environment, stdout=subprocess.DEVNULL,
                                 stderr=subprocess.PIPE, text=True, start_new_session=True,
                                 preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        deadline = time.monotonic() + 900.0
        while sweep.poll() is None and written_cells(out / "results.sqlite") < 1:
            if time.monotonic() > deadline:
                raise RuntimeError("no cell written in 900 s")
            time.sleep(0.05)
        time.sleep(settle)  # the workers in their next cells
        if sweep.poll() is not None:
            raise RuntimeError(f"the sweep ended before its interrupt: {sweep.stderr.read()}")
        sent = time.monotonic()
        os.killpg(sweep.pid, signal.SIGINT)
        sweep.wait()
        took = time.monotonic() - sent
        lines = sweep.stderr.read().strip().splitlines()
        return took, sweep.returncode, lines[-1] if lines else ""
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--engines", default="local,ray")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--hogs", default="0,3", help="comma-separated: CPU hogs per set")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--settle", type=float, default=0.5,
                        help="s between the first written cell and the SIGINT")
    args = parser.parse_args()
    for hogs in (int(h) for h in args.hogs.split(",")):
        spinning = [subprocess.Popen([sys.executable, "-c", "while 1: pass"])
                    for _ in range(hogs)]
        try:
            for engine in args.engines.split(","):
                figures = []
                for run in range(args.runs):
                    took, code, last = interrupt_once(engine, args.workers, args.settle)
                    figures.append(took)
                    print(f"{engine}, {hogs} hogs, run {run + 1}: {took:.2f} s to exit, "
                          f"exit code {code}, load {os.getloadavg()[0]:.1f}: {last}",
                          flush=True)
                print(f"{engine}, {hogs} hogs: median {statistics.median(figures):.2f} s, "
                      f"max {max(figures):.2f} s over {len(figures)} runs", flush=True)
        finally:
            for hog in spinning:
                hog.kill()
                hog.wait()


if __name__ == "__main__":
    main()
