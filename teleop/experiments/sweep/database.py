"""The results database of a sweep: one SQLite file, one row per finished cell
(docs/sweep.md).

Only the sweep's driver writes, one transaction per cell, committed as the cell finishes
(WAL journal, ``synchronous=FULL``): a sweep killed at any moment leaves every written row
whole and the file readable. The key is the cell's (a hash of its inputs) and the primary
key: a cell is never written twice, and re-running the same sweep skips the cells the file
holds. The file marks itself as this program's (SQLite's ``application_id``), so another
program's database is refused, never written into.
"""

from __future__ import annotations

import json
import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Mapping

#: ``PRAGMA application_id`` of a results database: "CJMS".
APPLICATION_ID = 0x434A4D53

#: ``PRAGMA user_version``: the layout of the tables below.
SCHEMA_VERSION = 1

#: The metrics copied into columns of their own, to filter and sort on in SQL.
METRIC_COLUMNS = ("hole_error_max_m", "ee_position_error_max_m", "port_force_max_n",
                  "constraint_error_max_m", "failed_steps", "step_time_median_us")

#: The inputs copied into columns of their own.
INPUT_COLUMNS = ("scenario", "controller", "seed", "plant")

_CREATE = f"""
CREATE TABLE IF NOT EXISTS cells (
    key TEXT PRIMARY KEY,
    inputs TEXT NOT NULL,
    status TEXT NOT NULL,
    reason TEXT,
    metrics TEXT,
    scenario TEXT NOT NULL, controller TEXT NOT NULL, seed INTEGER NOT NULL, plant TEXT NOT NULL,
    {", ".join(f"{name} REAL" for name in METRIC_COLUMNS)},
    elapsed_s REAL,
    attempts INTEGER NOT NULL,
    worker TEXT,
    version TEXT,
    finished_at REAL NOT NULL
)"""

#: The file name of a sweep's database in its folder.
DATABASE_NAME = "results.sqlite"


@dataclass(frozen=True)
class CellRow:
    """One finished cell as stored."""

    key: str
    inputs: dict[str, Any]
    status: str
    reason: str | None
    metrics: dict[str, Any] | None
    elapsed_s: float | None
    attempts: int
    worker: str | None
    version: str | None
    finished_at: float

    def metric(self, name: str) -> float | None:
        """A metric of a done cell (None where it does not apply or the cell failed)."""
        return None if self.metrics is None else self.metrics.get(name)


class ResultsDatabase:
    """A sweep's results file (created when missing); ``ValueError`` for a file that is not
    one (another program's SQLite file, not SQLite at all, a newer layout)."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        try:
            self._connection = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
        except sqlite3.Error as error:
            raise ValueError(f"{self.path}: cannot open the results database ({error})") from None
        try:
            self._prepare()
        except sqlite3.DatabaseError as error:
            self._connection.close()
            raise ValueError(f"{self.path}: not a results database ({error})") from None
        except ValueError:
            self._connection.close()
            raise

    def _prepare(self) -> None:
        """Mark a new file as a results database and create its table, in one transaction
        (two processes opening a new file at once: one creates, the other finds it)."""
        db = self._connection
        db.execute("PRAGMA journal_mode=WAL")
        db.execute("PRAGMA synchronous=FULL")
        db.execute("BEGIN IMMEDIATE")
        try:
            application = db.execute("PRAGMA application_id").fetchone()[0]
            tables = db.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]
            if application == 0 and tables == 0:
                db.execute(f"PRAGMA application_id={APPLICATION_ID}")
                db.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
                db.execute(_CREATE)
            elif application != APPLICATION_ID:
                raise ValueError(f"{self.path}: an SQLite file of another program, not a "
                                 "sweep's results database")
            else:
                version = db.execute("PRAGMA user_version").fetchone()[0]
                if version != SCHEMA_VERSION:
                    raise ValueError(f"{self.path}: results database layout {version}, this "
                                     f"version reads {SCHEMA_VERSION}")
            db.execute("COMMIT")
        except BaseException:
            db.execute("ROLLBACK")
            raise

    def close(self) -> None:
        self._connection.close()

    def __enter__(self) -> "ResultsDatabase":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def keys(self, status: str | None = None) -> set[str]:
        """The keys of the cells held (of ``status`` only, when given)."""
        if status is None:
            rows = self._connection.execute("SELECT key FROM cells")
        else:
            rows = self._connection.execute("SELECT key FROM cells WHERE status = ?", (status,))
        return {key for (key,) in rows}

    def write(self, key: str, inputs: Mapping[str, Any], outcome: Mapping[str, Any],
              attempts: int) -> bool:
        """Store a finished cell in one transaction; False (nothing written) when the file
        already holds its key (another sweep wrote it first)."""
        metrics = outcome.get("metrics")
        values = {
            "key": key, "inputs": _json(inputs), "status": outcome["status"],
            "reason": outcome.get("reason"), "metrics": None if metrics is None else _json(metrics),
            **{name: inputs.get(name, default) for name, default
               in zip(INPUT_COLUMNS, (None, None, 0, "kinematic"))},
            **{name: None if metrics is None else _number(metrics.get(name))
               for name in METRIC_COLUMNS},
            "elapsed_s": outcome.get("elapsed_s"), "attempts": int(attempts),
            "worker": outcome.get("worker"), "version": outcome.get("version"),
            "finished_at": time.time(),
        }
        names = ", ".join(values)
        marks = ", ".join("?" for _ in values)
        db = self._connection
        try:
            db.execute("BEGIN IMMEDIATE")
            db.execute(f"INSERT INTO cells ({names}) VALUES ({marks})", tuple(values.values()))
            db.execute("COMMIT")
        except sqlite3.IntegrityError:
            db.execute("ROLLBACK")
            return False
        except BaseException as error:
            if db.in_transaction:
                db.execute("ROLLBACK")
            if isinstance(error, sqlite3.OperationalError):  # locked past 30 s, disk full
                raise ValueError(f"{self.path}: cannot write cell {key}: {error}") from None
            raise
        return True

    def delete(self, keys: Iterable[str]) -> None:
        """Forget these cells (``--retry-failed`` runs failed cells again)."""
        db = self._connection
        db.execute("BEGIN IMMEDIATE")
        db.executemany("DELETE FROM cells WHERE key = ?", [(key,) for key in keys])
        db.execute("COMMIT")

    def rows(self, keys: Iterable[str] | None = None) -> list[CellRow]:
        """The cells held (those of ``keys`` only, when given), in the order they finished."""
        query = ("SELECT key, inputs, status, reason, metrics, elapsed_s, attempts, worker, "
                 "version, finished_at FROM cells ORDER BY finished_at, key")
        wanted = None if keys is None else set(keys)
        found = []
        for row in self._connection.execute(query):
            if wanted is not None and row[0] not in wanted:
                continue
            found.append(CellRow(row[0], json.loads(row[1]), row[2], row[3],
                                 None if row[4] is None else json.loads(row[4]), row[5],
                                 row[6], row[7], row[8], row[9]))
        return found

    def row(self, key_or_prefix: str) -> CellRow:
        """The one cell whose key is ``key_or_prefix`` or starts with it (``ValueError``
        when none or several)."""
        matches = [row for row in self.rows() if row.key.startswith(key_or_prefix)]
        if len(matches) != 1:
            raise ValueError(f"{'no' if not matches else len(matches)} cells of {self.path} "
                             f"have a key starting with {key_or_prefix!r}")
        return matches[0]

    def versions(self) -> list[str]:
        return sorted({v or "unknown" for (v,) in self._connection.execute(
            "SELECT DISTINCT version FROM cells")})


def _json(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None
