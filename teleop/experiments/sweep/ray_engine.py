"""The Ray engine: each cell a Ray task (docs/sweep.md).

On a local instance (started here: as many CPUs as workers, no dashboard) or an existing
cluster (``address``; every node needs this package installed). A task whose worker dies
is retried by Ray (``max_retries``); a task still running ``grace`` seconds past the cell's
time limit is cancelled (``ray.cancel(force=True)`` kills its worker) and the cell failed.
As many tasks are in flight as there are workers, so a task starts when it is submitted
and its clock is the cell's.
"""

from __future__ import annotations

import importlib.util
import os
import secrets
import shutil
import socket
import subprocess
import sys
import tempfile
import time
from collections import deque
from pathlib import Path
from typing import Any, Callable, Iterator

from .cell import FAILED, run_cell
from .pool import GRACE_S, SINGLE_THREADED, Finished
from .spec import Cell


#: Set before Ray is imported: Ray's switch for its cluster mode (on by default on Linux);
#: off, Ray takes 127.0.0.1 as the node's address, so a local instance's servers listen on
#: loopback only (else on this machine's network address). Not set for an existing cluster.
LOOPBACK_ONLY = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0"}


#: Longest folder a local instance's session files go in: Ray makes its Unix sockets at
#: ``FOLDER/session_<date>_<time>_<micros>_<pid>/sockets/plasma_store`` (63 more bytes),
#: and a socket's path holds at most 107 bytes on Linux (``sun_path``).
LONGEST_RAY_FOLDER = 107 - 63


def ray_folder(out: Path) -> tuple[Path, bool]:
    """Where a local instance keeps its session files (sockets, logs, spilled objects):
    ``out/ray``, or a fresh folder under the system's temporary folder when that path is too
    long for a Unix socket (:data:`LONGEST_RAY_FOLDER`); and whether it is such a temporary
    folder, to be removed when the instance stops."""
    inside = (out / "ray").absolute()
    if len(os.fsencode(inside)) <= LONGEST_RAY_FOLDER:
        return inside, False
    return Path(tempfile.mkdtemp(prefix="teleop-ray-")), True


def check_ray() -> None:
    """``ValueError`` unless Ray is installed (nothing imported)."""
    if importlib.util.find_spec("ray") is None:
        raise ValueError("--engine ray needs Ray: pip install -e \".[ray]\"")


#: Seconds to wait for a cluster's address to answer before refusing it (``ray.init`` itself
#: waits without end for an address where nothing listens, or where something that is not
#: Ray does).
CONNECT_TIMEOUT_S = 5.0

#: A Ray head's address is its GCS, a gRPC server: to HTTP/2's client preface and an empty
#: SETTINGS frame it answers with a frame of its own whose 9-byte header has type 4
#: (SETTINGS, RFC 9113 section 3.4).
HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n" + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])
FRAME_HEADER_BYTES = 9
SETTINGS_FRAME = 4


def check_address(address: str) -> None:
    """``ValueError`` unless ``address`` is ``HOST:PORT`` and a gRPC server (a Ray head)
    answers there within :data:`CONNECT_TIMEOUT_S`."""
    host, _, port = address.rpartition(":")
    if address.startswith("ray://") or not host or not port.isdigit():
        raise ValueError(f"--address must be HOST:PORT of a Ray cluster's head, got {address!r}")
    deadline = time.monotonic() + CONNECT_TIMEOUT_S
    try:
        with socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S) as connection:
            connection.sendall(HTTP2_PREFACE)
            answer = b""
            while len(answer) < FRAME_HEADER_BYTES:
                connection.settimeout(max(deadline - time.monotonic(), 1e-3))
                chunk = connection.recv(FRAME_HEADER_BYTES - len(answer))
                if not chunk:
                    break
                answer += chunk
    except TimeoutError:
        raise ValueError(f"the Ray cluster at {address} did not answer within "
                         f"{CONNECT_TIMEOUT_S:g} s: is it a Ray head's address?") from None
    except OSError as error:
        raise ValueError(f"cannot reach the Ray cluster at {address}: "
                         f"{error.strerror or error}") from None
    if len(answer) < FRAME_HEADER_BYTES or answer[3] != SETTINGS_FRAME:
        raise ValueError(f"{address} is not a Ray cluster's head: it does not answer as "
                         "a gRPC server")


def _import_ray(local: bool):
    """Ray, imported for a local instance on loopback (``local``) or a cluster."""
    check_ray()
    if local and "ray" not in sys.modules:
        for name, value in LOOPBACK_ONLY.items():
            os.environ.setdefault(name, value)
        # token authentication (Ray's default), its token in this process's environment,
        # inherited by Ray's processes, not in the file ~/.ray/auth_token that Ray would
        # write; read when Ray is imported
        if "RAY_AUTH_MODE" not in os.environ:
            os.environ["RAY_AUTH_MODE"] = "token"
            os.environ.setdefault("RAY_AUTH_TOKEN", secrets.token_hex(32))
    import ray

    return ray


def run_cell_task(key: str, inputs: dict[str, Any], time_limit: float) -> tuple[str, dict, float]:
    """A Ray task: the cell's outcome and the time it started (the worker's clock)."""
    started = time.time()
    return key, run_cell(inputs, time_limit), started


#: Ray's processes left running by :func:`_terminate_together`: the GCS (``ray.shutdown``
#: disconnects from it first, and waits 5 s for a dead one) and the reaper (last, by Ray).
KEPT_UNTIL_SHUTDOWN = ("gcs_server", "reaper")


def _terminate_together(ray) -> None:
    """Stop every process of the local instance but :data:`KEPT_UNTIL_SHUTDOWN` at once:
    SIGTERM to all, a wait of at most :data:`TERMINATE_WAIT_S` for them together, SIGKILL to
    those left (Ray's monitor outlives a SIGTERM by more than 1 s). ``ray.shutdown`` then
    finds them gone, where it sends each its SIGTERM and waits up to 1 s for it in turn."""
    node = getattr(ray._private.worker, "_global_node", None)
    if node is None:
        return
    processes = [info.process for kind, infos in node.all_processes.items()
                 if kind not in KEPT_UNTIL_SHUTDOWN for info in infos]
    for process in processes:
        if process.poll() is None:
            process.terminate()
    deadline = time.monotonic() + TERMINATE_WAIT_S
    for process in processes:
        try:
            process.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


#: How long :func:`_terminate_together` waits for Ray's processes to end on SIGTERM (s).
TERMINATE_WAIT_S = 0.2


class RayEngine:
    """Cells as Ray tasks, at most ``workers`` in flight."""

    def __init__(self, workers: int, retries: int = 2, address: str | None = None,
                 grace: float = GRACE_S, out: str | Path = ".") -> None:
        self.workers, self.retries, self.address, self.grace = workers, retries, address, grace
        self.out = Path(out)
        self.started_instance = False
        self._temporary_folder: Path | None = None

    def connect(self):
        """Ray, connected: to the cluster at ``address``, else to a local instance started
        here (its session files under :func:`ray_folder`, token authentication)."""
        ray = _import_ray(local=not self.address)
        if ray.is_initialized():
            return ray
        options = dict(include_dashboard=False, log_to_driver=False, configure_logging=False,
                       runtime_env={"env_vars": SINGLE_THREADED})
        try:
            if self.address:
                ray.init(address=self.address, **options)
            else:
                folder, temporary = ray_folder(self.out)
                self._temporary_folder = folder if temporary else None
                ray.init(num_cpus=self.workers, _temp_dir=str(folder), **options)
                self.started_instance = True
        except (ConnectionError, RuntimeError, ValueError) as error:
            where = f"the Ray cluster at {self.address}" if self.address else "a local Ray instance"
            raise ValueError(f"cannot start or reach {where}: {' '.join(str(error).split())}") from None
        return ray

    def shutdown(self) -> None:
        """Stop the local instance this engine started (an existing cluster stays up)."""
        if self.started_instance:
            _terminate_together(sys.modules["ray"])
            sys.modules["ray"].shutdown()
            self.started_instance = False
        if self._temporary_folder is not None:
            shutil.rmtree(self._temporary_folder, ignore_errors=True)
            self._temporary_folder = None

    def run(self, cells: list[Cell], time_limit: float,
            on_start: Callable[[Cell], None] | None = None) -> Iterator[Finished]:
        """Run ``cells``; yields each one's :class:`Finished` in the order they end."""
        ray = self.connect()
        task = ray.remote(num_cpus=1, max_retries=self.retries, retry_exceptions=False)(
            run_cell_task)
        queue = deque(cells)
        in_flight: dict[Any, tuple[Cell, float]] = {}
        last_end: dict[str, float] = {}
        try:
            while queue or in_flight:
                while queue and len(in_flight) < self.workers:
                    cell = queue.popleft()
                    in_flight[task.remote(cell.key, cell.inputs, time_limit)] = (
                        cell, time.monotonic())
                    if on_start is not None:
                        on_start(cell)
                ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=1.0)
                for ref in ready:
                    cell, submitted = in_flight.pop(ref)
                    yield self._finished(ray, ref, cell, submitted, last_end)
                now = time.monotonic()
                for ref, (cell, submitted) in list(in_flight.items()):
                    if now > submitted + time_limit + self.grace:
                        ray.cancel(ref, force=True)
                        del in_flight[ref]
                        yield Finished(cell, {
                            "status": FAILED, "metrics": None, "elapsed_s": now - submitted,
                            "reason": f"time limit {time_limit:g} s exceeded and no answer "
                                      f"{self.grace:g} s later: its task was cancelled"}, 1)
        finally:
            # a cluster outlives this run: its tasks are cancelled. A local instance is not:
            # its shutdown ends their workers, and a cancel racing a task's completion makes
            # Ray's core worker end this process with exit 1 (Ray's check "Tried to complete
            # task that was not pending", ray-project/ray#54798)
            if not self.started_instance:
                for ref in in_flight:
                    ray.cancel(ref, force=True)

    def _finished(self, ray, ref, cell: Cell, submitted: float,
                  last_end: dict[str, float]) -> Finished:
        try:
            _, outcome, started = ray.get(ref)
        except ray.exceptions.RayError as error:  # its worker died more than retries times
            reason = " ".join(str(error).split())[:300]
            return Finished(cell, {"status": FAILED, "metrics": None,
                                   "elapsed_s": time.monotonic() - submitted,
                                   "reason": f"{type(error).__name__}: {reason}"},
                            self.retries + 1)
        worker = outcome.get("worker", "")
        gap = None if worker not in last_end else started - last_end[worker]
        last_end[worker] = started + outcome.get("elapsed_s", 0.0)
        return Finished(cell, outcome, 1, gap)
