"""The Ray engine: each cell a Ray task (docs/sweep.md).

On a local instance (started here: as many CPUs as workers, no dashboard) or an existing
cluster (``address``; every node needs this package installed). A cell whose worker dies
is run again by the driver, up to ``retries`` more times (as the local pool does; Ray's
own ``max_retries`` is 0); a task still running ``grace`` seconds past the cell's time
limit ends its own worker (:mod:`.worker_deadline`: no cancel, which can race the task's
end and crash the driver) and the cell is failed. As many tasks are in flight as there
are workers, so a task starts when it is submitted and its clock is the cell's.
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
from .worker_deadline import ended_past


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


def run_cell_task(key: str, inputs: dict[str, Any], time_limit: float,
                  grace: float) -> tuple[str, dict, float]:
    """A Ray task: the cell's outcome and the time it started (the worker's clock); its
    worker's process ended by the kernel ``grace`` seconds past the time limit
    (:func:`.worker_deadline.ended_past`)."""
    started = time.time()
    with ended_past(time_limit + grace):
        outcome = run_cell(inputs, time_limit)
    return key, outcome, started


#: How long past a task's own deadline (the cell's time limit and the grace) the driver
#: waits for it to end before failing its cell without an answer (s): a worker that did
#: not end itself (stopped, say) is cancelled on a cluster, left to the shutdown of the
#: local instance this engine started (its CPU stays taken until then).
DEADLINE_MARGIN_S = 30.0


#: Ray's processes left running by :func:`_terminate_together`: the GCS (``ray.shutdown``
#: disconnects from it first, and waits 5 s for a dead one) and the reaper (last, by Ray).
KEPT_UNTIL_SHUTDOWN = ("gcs_server", "reaper")

#: Ray's processes :func:`_terminate_together` kills at once: the autoscaler's monitor,
#: asleep between its updates, outlives a SIGTERM by about 1 s (0.98 s measured at load
#: 14, where the raylet, the dashboard and the log monitor ended within 70 ms), and a
#: local instance's monitor holds nothing to save.
KILLED_AT_ONCE = ("monitor",)


def _terminate_together(ray) -> None:
    """Stop every process of the local instance but :data:`KEPT_UNTIL_SHUTDOWN` at once:
    SIGKILL to those of :data:`KILLED_AT_ONCE`, SIGTERM to the others, a wait of at most
    :data:`TERMINATE_WAIT_S` for them together, SIGKILL to those left. ``ray.shutdown``
    then finds them gone, where it sends each its SIGTERM and waits up to 1 s for it in
    turn."""
    node = getattr(ray._private.worker, "_global_node", None)
    if node is None:
        return
    processes = [(kind, info.process) for kind, infos in node.all_processes.items()
                 if kind not in KEPT_UNTIL_SHUTDOWN for info in infos]
    for kind, process in processes:
        if process.poll() is None:
            if kind in KILLED_AT_ONCE:
                process.kill()
            else:
                process.terminate()
    deadline = time.monotonic() + TERMINATE_WAIT_S
    for _, process in processes:
        try:
            process.wait(max(0.0, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


#: The longest wait of the driver in ``ray.wait`` (s): Python runs a signal's handler only
#: once the call returns (Ray's wait does not look at signals), so a Ctrl-C stops the
#: sweep up to this late (it was 1 s: half of the 1 s a stop took at load 12).
WAIT_S = 0.05

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
        # ``ray.shutdown`` imports this first (to stop compiled graphs, which a sweep has
        # none of): 0.18 s of a Ctrl-C's stop at load 14, paid here instead
        importlib.import_module("ray.dag.compiled_dag_node")
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
        task = ray.remote(num_cpus=1, max_retries=0, retry_exceptions=False)(run_cell_task)
        queue: deque[tuple[Cell, int]] = deque((cell, 0) for cell in cells)
        in_flight: dict[Any, tuple[Cell, float, int]] = {}
        last_end: dict[str, float] = {}
        try:
            while queue or in_flight:
                while queue and len(in_flight) < self.workers:
                    cell, attempts = queue.popleft()
                    in_flight[task.remote(cell.key, cell.inputs, time_limit, self.grace)] = (
                        cell, time.monotonic(), attempts + 1)
                    if on_start is not None:
                        on_start(cell)
                ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=WAIT_S)
                for ref in ready:
                    cell, submitted, attempts = in_flight.pop(ref)
                    finished = self._finished(ray, ref, cell, submitted, attempts, time_limit,
                                              last_end)
                    if finished is None:
                        queue.appendleft((cell, attempts))
                    else:
                        yield finished
                now = time.monotonic()
                for ref, (cell, submitted, attempts) in list(in_flight.items()):
                    if now > submitted + time_limit + self.grace + DEADLINE_MARGIN_S:
                        del in_flight[ref]
                        if not self.started_instance:
                            ray.cancel(ref, force=True)
                        yield Finished(cell, {
                            "status": FAILED, "metrics": None, "elapsed_s": now - submitted,
                            "reason": f"time limit {time_limit:g} s exceeded and no answer "
                                      f"{self.grace + DEADLINE_MARGIN_S:g} s later: its "
                                      "worker did not end itself"}, attempts)
        finally:
            # a cluster outlives this run: its tasks are cancelled. A local instance is not:
            # its shutdown ends their workers, and a cancel racing a task's completion makes
            # Ray's core worker end this process with exit 1 (Ray's check "Tried to complete
            # task that was not pending", ray-project/ray#54798)
            if not self.started_instance:
                for ref in in_flight:
                    ray.cancel(ref, force=True)

    def _finished(self, ray, ref, cell: Cell, submitted: float, attempts: int,
                  time_limit: float, last_end: dict[str, float]) -> Finished | None:
        """The cell's end, or None when its worker died and it runs again."""
        try:
            _, outcome, started = ray.get(ref)
        except ray.exceptions.RayTaskError as error:  # the task's own code raised
            return self._failed(cell, submitted, attempts,
                                f"{type(error).__name__}: {' '.join(str(error).split())}")
        except ray.exceptions.RayError as error:  # its worker or its node died
            elapsed = time.monotonic() - submitted
            if elapsed >= time_limit + self.grace:  # it ended itself: stuck, not run again
                return self._failed(cell, submitted, attempts,
                                    f"time limit {time_limit:g} s exceeded and no answer "
                                    f"{self.grace:g} s later: its worker ended itself")
            if attempts <= self.retries:
                return None
            return self._failed(cell, submitted, attempts,
                                f"{type(error).__name__}: {' '.join(str(error).split())}")
        worker = outcome.get("worker", "")
        gap = None if worker not in last_end else started - last_end[worker]
        last_end[worker] = started + outcome.get("elapsed_s", 0.0)
        return Finished(cell, outcome, attempts, gap)

    def _failed(self, cell: Cell, submitted: float, attempts: int, reason: str) -> Finished:
        return Finished(cell, {"status": FAILED, "metrics": None,
                               "elapsed_s": time.monotonic() - submitted,
                               "reason": f"{reason[:300]} (attempt {attempts} of "
                                         f"{self.retries + 1})"}, attempts)
