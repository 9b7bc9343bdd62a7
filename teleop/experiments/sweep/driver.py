"""Run a sweep: the cells the results database does not hold yet, on an engine, each
written as it finishes; the progress; the figures of the run (docs/sweep.md)."""

from __future__ import annotations

import contextlib
import os
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

from .cell import DONE, FAILED
from .database import DATABASE_NAME, ResultsDatabase
from .pool import Finished, LocalPool
from .spec import SweepSpec, describe_cell

#: The engines, by name.
ENGINES = ("local", "ray")


@dataclass
class SweepRun:
    """What one run of a sweep did: the cells of the grid, those the database held before
    (skipped), those run now (done, failed), those another sweep wrote first, the wall
    time, and each engine's gap between a worker's cells (s)."""

    total: int
    skipped: int = 0
    done: int = 0
    failed: int = 0
    written_elsewhere: int = 0
    wall_s: float = 0.0
    cell_seconds: list[float] = field(default_factory=list)
    dispatch_gaps_s: list[float] = field(default_factory=list)

    @property
    def ran(self) -> int:
        return self.done + self.failed

    def throughput_line(self, workers: int) -> str:
        """Cells per minute, the mean cell, the engine's overhead per cell."""
        if not self.ran:
            return f"no cell to run: the database holds all {self.total}"
        per_minute = 60.0 * self.ran / self.wall_s if self.wall_s > 0 else float("inf")
        mean_cell = statistics.fmean(self.cell_seconds) if self.cell_seconds else 0.0
        line = (f"{self.ran} cells in {self.wall_s / 60:.1f} min on {workers} workers: "
                f"{per_minute:.1f} cells/min, mean cell {mean_cell:.1f} s")
        if self.dispatch_gaps_s:
            gap = statistics.median(self.dispatch_gaps_s)
            share = f", {100 * gap / mean_cell:.2f} % of a cell" if mean_cell > 0 else ""
            line += f"; between two cells on a worker {1e3 * gap:.1f} ms median{share}"
        return line


def default_workers() -> int:
    """As many workers as the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def make_engine(engine: str, workers: int, retries: int, address: str | None,
                out: str | Path = "."):
    """The engine by name (``ValueError`` for an unknown one, Ray missing, fewer than one
    worker, negative retries); a local Ray instance keeps its files under ``out``."""
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 0:
        raise ValueError(f"retries must be >= 0, got {retries}")
    if engine == "local":
        if address:
            raise ValueError("--address needs --engine ray")
        return LocalPool(workers, retries)
    if engine == "ray":
        from .ray_engine import RayEngine, check_address, check_ray

        check_ray()
        if address:
            check_address(address)
        return RayEngine(workers, retries, address, out=out)
    raise ValueError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")


def run_sweep(spec: SweepSpec, out: str | Path, engine: str = "local",
              workers: int | None = None, retries: int = 2, address: str | None = None,
              retry_failed: bool = False, console: TextIO | None = None,
              progress: bool = True) -> SweepRun:
    """Run the cells of ``spec`` that ``out``'s database does not hold (with
    ``retry_failed``, also those it holds as failed), writing each as it finishes.

    A ``KeyboardInterrupt`` stops the engine (the cells in flight are lost) and propagates:
    every finished cell is already written, and the same call resumes. From a script, call
    it under ``if __name__ == "__main__":`` (the pool's workers are spawned and import the
    main module).
    """
    console = console or sys.stderr
    workers = default_workers() if workers is None else workers
    runner = make_engine(engine, workers, retries, address, out)
    folder = sweep_folder(out)
    cells = spec.cells()
    with ResultsDatabase(folder / DATABASE_NAME) as database:
        if retry_failed:
            failed = database.keys(FAILED)
            database.delete(cell.key for cell in cells if cell.key in failed)
        held = database.keys()
        todo = [cell for cell in cells if cell.key not in held]
        run = SweepRun(total=len(cells), skipped=len(cells) - len(todo))
        if not todo:
            return run
        bar = Progress(len(todo), console, progress)
        started = time.monotonic()
        try:
            with contextlib.closing(runner.run(todo, spec.time_limit)) as finishing:
                for finished in finishing:  # closed on any exit: the workers stopped
                    _record(database, finished, run)
                    bar.update(run, finished)
        finally:
            run.wall_s = time.monotonic() - started
            bar.close()
            if hasattr(runner, "shutdown"):
                runner.shutdown()
    return run


def _record(database: ResultsDatabase, finished: Finished, run: SweepRun) -> None:
    written = database.write(finished.cell.key, finished.cell.inputs, finished.outcome,
                             finished.attempts)
    if not written:
        run.written_elsewhere += 1
        return
    if finished.outcome["status"] == DONE:
        run.done += 1
    else:
        run.failed += 1
    if finished.outcome.get("elapsed_s") is not None:
        run.cell_seconds.append(finished.outcome["elapsed_s"])
    if finished.dispatch_gap_s is not None:
        run.dispatch_gaps_s.append(finished.dispatch_gap_s)


def sweep_folder(out: str | Path) -> Path:
    """``out`` made if missing (``ValueError`` when it cannot be, or is a file)."""
    folder = Path(out)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"--out {str(folder)!r} exists and is not a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise ValueError(f"cannot make the sweep folder {str(folder)!r}: "
                         f"{error.strerror or error}") from None
    return folder


class Progress:
    """On a terminal a tqdm bar (cells, failed, rate, time left); else a line per 5 % of
    the cells or per minute, whichever comes first, and one per failed cell."""

    def __init__(self, total: int, console: TextIO, enabled: bool) -> None:
        self.total, self.console, self.enabled = total, console, enabled
        self._bar = None
        self._started = self._last_line = time.monotonic()
        self._last_count = 0
        if enabled and console.isatty():
            from tqdm import tqdm

            self._bar = tqdm(total=total, unit="cell", file=console, dynamic_ncols=True)

    def update(self, run: SweepRun, finished: Finished) -> None:
        if not self.enabled:
            return
        if finished.outcome["status"] == FAILED:
            self._write(f"failed: {describe_cell(finished.cell.inputs)} "
                        f"[{finished.cell.key}]: {finished.outcome.get('reason')}")
        if self._bar is not None:
            self._bar.update(1)
            self._bar.set_postfix(failed=run.failed, refresh=False)
            return
        count, now = run.ran + run.written_elsewhere, time.monotonic()
        if (count - self._last_count >= max(1, self.total // 20) or now - self._last_line >= 60
                or count == self.total):
            elapsed = now - self._started
            left = elapsed / count * (self.total - count) if count else 0.0
            print(f"sweep: {count}/{self.total} cells ({run.failed} failed), "
                  f"{60 * count / max(elapsed, 1e-9):.1f} cells/min, about "
                  f"{left / 60:.1f} min left", file=self.console, flush=True)
            self._last_count, self._last_line = count, now

    def _write(self, line: str) -> None:
        if self._bar is not None:
            self._bar.write(line, file=self.console)
        else:
            print(line, file=self.console, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
