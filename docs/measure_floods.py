"""The control loop's rate under floods, in one run (issue 33 item 6, docs/inputs.md
"Floods"): the page's server with its control loop at 1 kHz, a hole on link 6, and a
network master streaming from another process at 500 Hz; then, each from a process of
its own,

* ``gui``: one browser connection (the right Origin and token) sending 10,000 gizmo-drag
  messages as fast as its socket takes them;
* ``udp``: 300,000 datagrams at the master's port, a third each malformed (random bytes),
  forged (a command with a random tag) and of another rig (tagged with another key);
* ``both`` at once;
* ``cpu``, the control: a process that only computes for 2 s, what the UDP flood's sender
  takes of the machine's two cores, sending nothing.

Each phase's loop rate is measured from the control thread's tick count, sampled every
50 ms: the mean over the flood and the worst 1 s window, as fractions of the baseline's
mean (the loop's first quiet seconds in the same run). Also printed: the master's
releases (the watchdog, 100 ms), what the receiver counted, what the inbox coalesced.

Run:  OPENBLAS_NUM_THREADS=1 python docs/measure_floods.py [--events 10000]
      [--datagrams 300000] [--repeat 1] [--json FILE]
(the machine's other work moves these figures: ``cpu`` shows by how much)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import threading
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from teleop import load_robot  # noqa: E402
from teleop.inputs import UdpMaster  # noqa: E402
from web.shared_priority import make_shared_realtime  # noqa: E402
from web.ui.server import run_server  # noqa: E402

KEY = bytes(range(32))
#: the real master, another process: holds still, streaming at 500 Hz until killed
MASTER = """
import sys, time
from teleop.inputs import MasterClient
client = MasterClient(int(sys.argv[1]), key=bytes.fromhex(sys.argv[2]))
print("streaming", flush=True)
due = time.perf_counter()
while True:  # late (the machine is busy), it skips what it missed rather than burst
    client.send_pose((0.0, 0.0, 0.0))
    client.feedback()
    due = max(due + 1 / 500.0, time.perf_counter())
    time.sleep(max(0.0, due - time.perf_counter()))
"""
#: the GUI flood: one connection with the page's Origin and token, gizmo drags
GUI_FLOOD = """
import math, sys, time, msgspec, viser
from viser._messages import TransformControlsUpdateMessage, ViewerCameraMessage
from websockets.sync.client import connect
url, origin, count = sys.argv[1], sys.argv[2], int(sys.argv[3])
x, y, z, *wxyz = (float(v) for v in sys.argv[4:11])
with connect(url, origin=origin, subprotocols=[f"viser-v{viser.__version__}"],
             open_timeout=30, max_size=None, max_queue=None) as socket:  # it reads nothing
    camera = ViewerCameraMessage((1.0, 0.0, 0.0, 0.0), (2.0, 0.0, 1.0), 1.0, 0.01, 100.0, 600,
                                 800, (0.0, 0.0, 0.5), (0.0, 0.0, 1.0))
    socket.send(msgspec.msgpack.encode(camera.as_serializable_dict()))  # a browser says where
    time.sleep(1.0)  # it looks first: viser counts it as connected from then on
    start = time.perf_counter()
    for k in range(count):
        message = TransformControlsUpdateMessage(
            "/gizmo", tuple(wxyz), (x + 0.01 * math.sin(k / 300), y, z))
        socket.send(msgspec.msgpack.encode(message.as_serializable_dict()))
    print("sent", count, "in", round(time.perf_counter() - start, 2), "s", flush=True)
    sys.stdin.read()  # connected until told: the server may still be reading them
"""
#: the UDP flood: malformed, forged and another rig's datagrams in turn, from two sockets
UDP_FLOOD = """
import os, socket, sys, time
from teleop.inputs.protocol import COMMAND_FORMAT, TAG_SIZE, VERSION, encode_command
port, count = int(sys.argv[1]), int(sys.argv[2])
forged = COMMAND_FORMAT.pack(b"CJMI", VERSION, 1, 0, 0, 5, 0.0, 0.05, 0, 0, 1, 0, 0, 0, 7, 9) \\
    + os.urandom(TAG_SIZE)
junk = [os.urandom(100) for _ in range(64)]
foreign = [encode_command("pose", (0.05, 0, 0, 1, 0, 0, 0), s, 0.0, key=bytes(32), stream=99)
           for s in range(1, 65)]
kinds = (lambda k: junk[k % 64], lambda k: forged, lambda k: foreign[k % 64])
sockets = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
start = time.perf_counter()
for k in range(count):
    sockets[k % 2].sendto(kinds[k % 3](k), ("127.0.0.1", port))
print("sent", count, "in", round(time.perf_counter() - start, 2), "s", flush=True)
"""


#: the control: a process that computes and sends nothing
CPU_HOG = """
import sys, time
end = time.perf_counter() + float(sys.argv[1])
print("computing", flush=True)
while time.perf_counter() < end:
    pass
sys.stdin.read()
"""


def thread_times() -> dict[str, tuple[float, float]]:
    """Every thread of this process by name (its kernel name where Python's is not known,
    numbered when two share one): the seconds it ran on a CPU and the seconds it waited,
    runnable, for one (``/proc/self/task/ID/schedstat``)."""
    names = {thread.native_id: thread.name for thread in threading.enumerate()}
    times: dict[str, tuple[float, float]] = {}
    for task in os.listdir("/proc/self/task"):
        try:
            with open(f"/proc/self/task/{task}/schedstat") as file:
                ran, waited = (int(field) * 1e-9 for field in file.read().split()[:2])
            if int(task) not in names:
                with open(f"/proc/self/task/{task}/comm") as file:
                    names[int(task)] = file.read().strip()
        except (OSError, ValueError):  # the thread ended meanwhile
            continue
        name, k = names[int(task)], 1
        while name in times:
            k += 1
            name = f"{names[int(task)]} {k}"
        times[name] = (ran, waited)
    return times


class TickSampler:
    """The control thread's tick count and every thread's CPU time every 50 ms, from a
    thread of its own."""

    def __init__(self, app) -> None:
        self.app = app
        self.samples: list[tuple[float, int]] = []
        self.threads: list[dict[str, tuple[float, float]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sampler", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        make_shared_realtime()  # as the server's threads: an ordinary thread of the process
        while not self._stop.is_set():  # preempted while it holds the GIL holds the loop
            self.threads.append(thread_times())
            self.samples.append((time.perf_counter(), self.app.ticker.ticks))
            time.sleep(0.05)

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def rates(self, start: float, end: float) -> tuple[float, float, str]:
        """The mean rate over [start, end] and the worst over its 1 s windows (Hz), and
        where the threads' time went in the worst window (the control thread's on a CPU
        and waiting for one, the busiest others' on a CPU; ms per s)."""
        times, ticks = (np.array(column, dtype=float) for column in zip(*self.samples))
        inside = np.flatnonzero((times >= start) & (times <= end))
        t, n = times[inside], ticks[inside]
        mean = (n[-1] - n[0]) / (t[-1] - t[0])
        worst, window = mean, (inside[0], inside[-1])
        for i in range(len(t)):
            j = np.searchsorted(t, t[i] + 1.0)
            if j < len(t) and (n[j] - n[i]) / (t[j] - t[i]) < worst:
                worst = (n[j] - n[i]) / (t[j] - t[i])
                window = (inside[i], inside[j])
        return float(mean), float(worst), self.where(*window)

    def where(self, first: int, last: int) -> str:
        """The threads' time between samples ``first`` and ``last`` (ms per s)."""
        seconds = self.samples[last][0] - self.samples[first][0]
        before, after = self.threads[first], self.threads[last]
        spent = {name: tuple(1e3 * (now - then) / seconds for now, then in
                             zip(after[name], before[name])) for name in after if name in before}
        ran, waited = spent.pop("control", (float("nan"), float("nan")))
        others = sorted(spent.items(), key=lambda item: -sum(item[1]))
        busiest = ", ".join(f"{name} {cpu:.0f}/{wait:.0f}" for name, (cpu, wait) in others[:4])
        total = [sum(column) for column in zip(*spent.values())]
        return (f"control thread on a CPU {ran:.0f}, waiting for one {waited:.0f}; the "
                f"others on a CPU/waiting for one {total[0]:.0f}/{total[1]:.0f} ({busiest}) "
                "ms/s")


def child(script: str, *args: object) -> subprocess.Popen:
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
         os.environ.get("PYTHONPATH", "")])}
    return subprocess.Popen([sys.executable, "-c", script, *map(str, args)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=environment)


def finish(process: subprocess.Popen, what: str) -> None:
    """Tell ``process`` to end (its stdin closed) and wait for it."""
    process.stdin.close()
    err = process.stderr.read()
    if process.wait(timeout=600) != 0:
        raise SystemExit(f"the {what} failed: {err.strip()[-2000:]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=10_000)
    parser.add_argument("--datagrams", type=int, default=300_000)
    parser.add_argument("--baseline", type=float, default=5.0, help="quiet seconds measured")
    parser.add_argument("--repeat", type=int, default=1, help="run the floods this many times")
    parser.add_argument("--json", help="also write the figures to this file")
    args = parser.parse_args()
    master = UdpMaster(port=0, key=KEY)
    server, app, control, ui = run_server(load_robot("sda10f"), port=8765, token="auto",
                                          inputs=[master], input_timeout=0.1,
                                          record_dir="/tmp/floods/sessions",
                                          scene_dir="/tmp/floods/scenes")
    app.constraints.add("hole", distance=0.08)
    port, token = server.get_port(), ui.access.token
    url = f"ws://127.0.0.1:{port}/?token={token}"
    origin = f"http://127.0.0.1:{port}"
    streamer = child(MASTER, master.port, KEY.hex())
    assert streamer.stdout is not None and "streaming" in streamer.stdout.readline()
    time.sleep(2.0)  # the loop settles, the master binds
    make_shared_realtime()  # this thread too polls the app while the floods run (the
    sampler = TickSampler(app)  # processes it starts run ordinary)
    results: dict[str, dict] = {}
    try:
        time.sleep(args.baseline)
        baseline, baseline_worst, quiet = sampler.rates(time.perf_counter() - args.baseline,
                                                        time.perf_counter())
        results["baseline"] = {"mean_hz": baseline, "worst_1s_hz": baseline_worst,
                               "worst_1s_threads": quiet}
        gizmo = ui.scene.target_gizmo
        goal = [*gizmo.position, *gizmo.wxyz]
        floods = {
            "gui": lambda: [child(GUI_FLOOD, url, origin, args.events, *goal)],
            "udp": lambda: [child(UDP_FLOOD, master.port, args.datagrams)],
            "both": lambda: [child(GUI_FLOOD, url, origin, args.events, *goal),
                             child(UDP_FLOOD, master.port, args.datagrams)],
            "cpu": lambda: [child(CPU_HOG, 2.0)]}
        last = np.array(goal[:3]) + [0.01 * np.sin((args.events - 1) / 300), 0.0, 0.0]
        for run, (name, start_flood) in ((run, flood) for run in range(args.repeat)
                                         for flood in floods.items()):
            before = master.counts_now()
            coalesced, applied = ui.inbox.coalesced, ui.inbox.applied
            paced = (ui.pacing.read, ui.pacing.coalesced, ui.pacing.delivered)
            start = time.perf_counter()
            processes = start_flood()
            said = [process.stdout.readline().strip() for process in processes]
            if name == "cpu":
                time.sleep(2.0)
            if name in ("gui", "both"):  # until the server has applied the last drag
                wait = time.monotonic() + 300.0
                while np.linalg.norm(app.console.inputs[0].gizmo.translation - last) > 1e-9:
                    if time.monotonic() > wait:
                        raise SystemExit("the last drag never reached the app")
                    time.sleep(0.01)
            end = time.perf_counter()
            for process in processes:
                finish(process, f"{name} flood")
            mean, worst, spent = sampler.rates(start, end)
            counts = master.counts_now()
            delta = {key: counts.get(key, 0) - before.get(key, 0) for key in counts
                     if counts.get(key, 0) != before.get(key, 0)}
            result = results[f"{name} {run + 1}"] = {
                "seconds": end - start, "mean_hz": mean, "worst_1s_hz": worst,
                "mean_fraction": mean / baseline, "worst_fraction": worst / baseline,
                "worst_1s_threads": spent, "scheduling": control.scheduling,
                "flooder": said, "udp_counts": delta,
                "inbox_coalesced": ui.inbox.coalesced - coalesced,
                "inbox_applied": ui.inbox.applied - applied,
                "paced_read_coalesced_delivered": [
                    now - then for now, then in zip((ui.pacing.read, ui.pacing.coalesced,
                                                     ui.pacing.delivered), paced)]}
            print(f"{name} ({run + 1}): {end - start:.1f} s, mean {mean:.0f} Hz ({mean / baseline:.3f} of "
                  f"baseline), worst 1 s {worst:.0f} Hz ({worst / baseline:.3f}); "
                  f"{'; '.join(said)}; releases {delta.get('releases', 0)}; "
                  f"counts {delta}; inbox coalesced {result['inbox_coalesced']}, "
                  f"applied {result['inbox_applied']}; messages read, coalesced, "
                  f"handed to viser {result['paced_read_coalesced_delivered']}; worst 1 s: "
                  f"{spent}; the control thread {control.scheduling}, the others "
                  f"{control.shared_scheduling or 'as they were'}",
                  flush=True)
            time.sleep(2.0)  # quiet between floods
        print(f"baseline: mean {baseline:.0f} Hz, worst 1 s {baseline_worst:.0f} Hz: {quiet}")
        for name in floods:
            runs = [results[f"{name} {run + 1}"] for run in range(args.repeat)]
            print(f"{name}: mean " + ", ".join(f"{r['mean_fraction']:.3f}" for r in runs)
                  + "; worst 1 s " + ", ".join(f"{r['worst_fraction']:.3f}" for r in runs))
    finally:
        sampler.stop()
        streamer.kill()
        streamer.wait()
        ui.stop()
        control.stop()
        app.devices.close()
        server.stop()
    if args.json:
        with open(args.json, "w") as file:
            json.dump(results, file, indent=1)


if __name__ == "__main__":
    main()
