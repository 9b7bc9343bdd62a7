"""The status panel: a line of a few plain words (what each robot's end effectors do, the
constraints placed and the link each is on, the force at each port in mN) and, one click
away in its "Details" folder, the control loop's rate and timing, what limits each
robot's end effectors in the controller's words, the one-sided constraints held, the
minimum distance, closest pair and collision pairs held, the console's state; a red
banner while the control loop falls behind (docs/design.md section 5.3)."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import viser

from constraints.collision import CollisionRows

from ..app import HISTORY_SECONDS, ControlThread, port_words, summary_words, supervision_words
from .port_forces import FORCE_ARROW_WORDS

BEHIND_COLOR = "#b91c1c"  # the banner of a control loop falling behind
#: at most one "control loop behind" notification in this long (s): the banner says it as
#: long as it lasts, and a rate hovering about the threshold on a busy machine raised a
#: notification every few seconds, stacked over the scene
BEHIND_NOTICE_INTERVAL = 60.0


def collision_words(rows: CollisionRows | None, active_pairs: list[str]) -> str:
    """The status's words on collisions: the minimum distance and the closest pair (of
    the rows the controller computed for its last step; nothing before a step or while
    collisions are off), and the pairs the controller holds at their bound."""
    if rows is None:
        return ""
    if math.isinf(rows.minimum_distance):
        words = "; no collision pair near"
    else:
        words = (f"; minimum distance {1e3 * rows.minimum_distance:.2f} mm "
                 f"({rows.closest_pair})")
    if active_pairs:
        words += f"; collision pairs held: {', '.join(active_pairs)}"
    return words


class StatusPanel:
    """The status panel of :class:`web.ui.TeleopUI`, a component owning its handles: the
    banner of a control loop falling behind, the few plain words always shown
    (:attr:`summary`) and the details in a folder closed by default (:attr:`details`).
    Built where the caller's GUI context puts it; the view thread calls :meth:`draw`.

    Parameters
    ----------
    gui : the server's GUI.
    control : the control thread (its timing, whether it falls behind, its error).
    ee_names : what the operator reads per EE frame.
    port_peak : the plots' largest port force over their window (N; None: no port).
    device_lines : each input device's status line, from a snapshot.
    notify : tells every browser (``notify(None, title, body, color=...)``).
    """

    def __init__(self, gui: viser.GuiApi, control: ControlThread, ee_names: dict[str, str],
                 port_peak: Callable[[], float | None],
                 device_lines: Callable[[dict], list[str]], notify: Callable[..., None]) -> None:
        self.control = control
        self.ee_names = ee_names
        self._port_peak = port_peak
        self._device_lines = device_lines
        self._notify = notify
        self._behind = ""  # the warning shown while the control loop falls behind
        self._behind_noticed = -math.inf  # when the last notification of it was raised (s)
        self.banner = gui.add_html("", visible=False)
        self.summary = gui.add_markdown("starting...")
        with gui.add_folder("Details", expand_by_default=False):
            self.details = gui.add_markdown("starting...")

    def show_error(self, words: str) -> None:
        """``words`` in both the summary and the details (the view failed)."""
        self.summary.content = self.details.content = words

    def _warn_behind(self) -> None:
        """A red banner above the status while the control loop achieves less than 95 % of
        its rate (``ControlThread.behind``), and a notification when it starts, at most
        one per :data:`BEHIND_NOTICE_INTERVAL`."""
        behind = self.control.behind()
        if bool(behind) != bool(self._behind):
            now = time.monotonic()
            if behind and now - self._behind_noticed >= BEHIND_NOTICE_INTERVAL:
                self._notify(None, "Control loop behind", behind, color="red")
                self._behind_noticed = now
            self.banner.visible = bool(behind)
        if behind and behind != self._behind:
            self.banner.content = (f'<div style="background:{BEHIND_COLOR};color:white;'
                                   f'padding:6px 8px;border-radius:4px;font-weight:600">'
                                   f'{behind}</div>')
        self._behind = behind

    def _summary(self, snapshot: dict) -> str:
        """The status line: per robot what each EE does in a few words
        (:func:`web.app.summary_words`), each constraint with the link it is on, each port's
        force in mN; the clutch when engaged."""
        names = [self.ee_names[frame] for frame in snapshot["ee_frames"]]
        lines = []
        for which, robot in snapshot["robots"].items():
            words = "; ".join(summary_words(each) if len(names) == 1 else
                              f"*{name}* {summary_words(each)}"
                              for name, each in zip(names, robot["limitations"]))
            lines.append(f"**{which}** {words}")
        placed = [f"{entry['id']} on `{entry['link']}`" for entry in snapshot["constraints"]]
        if placed:
            lines.append("placed: " + ", ".join(placed))
        ports = snapshot["robots"]["main"]["ports"]
        if ports:
            port_peak = self._port_peak()
            peak = "" if port_peak is None else \
                f"; the largest in the last {HISTORY_SECONDS:g} s {1e3 * port_peak:.2f} mN"
            lines.append(", ".join(f"port force {port.id} **{1e3 * port.magnitude:.2f} mN**"
                                   for port in ports) + f"{peak} ({FORCE_ARROW_WORDS})")
        if snapshot["clutch"]:
            lines.append("**clutch engaged**")
        return "  \n".join(lines)

    def draw(self, snapshot: dict) -> None:
        """The banner, the summary and the details of ``snapshot``."""
        self._warn_behind()
        self.summary.content = self._summary(snapshot)
        timing = self.control.timing()
        control = (f"**control{' BEHIND' if self._behind else ''}** "
                   f"{timing.achieved_rate:.0f} Hz achieved (target "
                   f"{snapshot['config'].rate:.0f} Hz), {100 * timing.on_time:.1f} % of ticks "
                   f"on time, lateness p99 {timing.lateness_p99_ms:.2f} ms, tick "
                   f"{timing.tick_p50_us:.0f} us ({timing.overhead_p50_us:.0f} us beyond the "
                   f"controllers{', physics included' if snapshot['plant'].physical else ''}; "
                   f"medians: controllers {timing.solve_p50_us:.0f} us, loop "
                   f"{timing.loop_p50_us:.0f} us, UI {timing.ui_p50_us:.0f} us), "
                   f"{timing.deadline_misses} deadline misses; {self.control.scheduling}"
                   f"{'; the other threads ' if self.control.shared_scheduling else ''}"
                   f"{self.control.shared_scheduling}")
        lines = [control]
        if snapshot["plant"].physical:
            lines.append(f"**plant** {snapshot['plant'].describe()}")
        if self.control.error:
            lines.append(f"**control error** {self.control.error}")
        names = [self.ee_names[frame] for frame in snapshot["ee_frames"]]
        for which, robot in snapshot["robots"].items():
            record, limitation = robot["record"], robot["limitation"]
            if len(names) == 1:
                words = f"**{which}** `{robot['spec']}` **{limitation.status}**: {limitation.words}"
                if record is not None:
                    words += (" (constraint "
                              f"{max(record.constraint_error, record.barrier_penetration):.1e} m, "
                              f"EE {1e3 * limitation.distance:.2f} mm from the target, "
                              f"step {record.step_time_us:.0f} us)")
            else:  # one status per robot, what keeps each EE from its target
                words = f"**{which}** `{robot['spec']}` **{limitation.status}**: " + "; ".join(
                    f"*{name}* {each.words} ({1e3 * each.distance:.2f} mm from its target)"
                    for name, each in zip(names, robot["limitations"]))
                if record is not None:
                    words += (" (constraint "
                              f"{max(record.constraint_error, record.barrier_penetration):.1e} m, "
                              f"step {record.step_time_us:.0f} us)")
            if robot["ports"]:
                words += f"; {port_words(robot['ports'])}"
            supervised = supervision_words(robot.get("supervision"))
            if supervised:
                words += f"; **{supervised}**"
            if robot["active_inequalities"]:
                words += (f"; one-sided constraints held: "
                          f"{', '.join(robot['active_inequalities'])}")
            words += collision_words(robot["collision_rows"], robot["active_pairs"])
            lines.append(words)
        console = [f"motion scale {snapshot['motion_scale']:g}"]
        if snapshot["clutch"]:
            console.insert(0, "**clutch engaged**: the gizmo moves alone" if len(names) == 1
                           else "**clutch engaged**: the gizmos move alone")
        lines.append(", ".join(console))
        lines += self._device_lines(snapshot)
        self.details.content = "  \n".join(lines)
