"""The end of a sweep (docs/sweep.md): each controller's statistics over its cells, the
worst cells, their own ``teleop compare`` reports and ``summary.html``, one self-contained
page (its figures embedded as base64 PNG, every text escaped, no other file needed but the
reports it links to); and one cell described for ``teleop sweep show``.
"""

from __future__ import annotations

import base64
import datetime
import html
import math
import shlex
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .cell import DONE, compare_command
from .database import DATABASE_NAME, CellRow, ResultsDatabase
from .spec import CELL_FIELDS, DEFAULT_TIME_LIMIT_S, SweepSpec, describe_cell

#: The summary page's name in the sweep's folder.
SUMMARY_NAME = "summary.html"

#: The folder of the cells' compare reports in the sweep's folder (one folder per key).
REPORTS_FOLDER = "reports"

#: The most cells the worst-cells list shows: on the page, and printed at the end of a run.
WORST_LISTED = 20
WORST_PRINTED = 10

#: A report's time beyond its cell's limit: the imports and the plots (s).
REPORT_MARGIN_S = 120.0


@dataclass(frozen=True)
class SummaryMetric:
    """One metric of the summary: its key in a cell's metrics (SI units), its name in the
    statistics (its unit's), its label, the unit shown and the factor from SI to it;
    ``summed``: its total over the cells means something (failed steps)."""

    key: str
    name: str
    label: str
    unit: str
    scale: float = 1.0
    summed: bool = False

    @property
    def heading(self) -> str:
        return f"{self.label} ({self.unit})" if self.unit else self.label

    def value(self, row: CellRow) -> float | None:
        """The row's value in the shown unit (None: failed, or does not apply)."""
        value = row.metric(self.key) if row.status == DONE else None
        return None if value is None else float(value) * self.scale


HOLE_ERROR = SummaryMetric("hole_error_max_m", "hole_error_max_um", "hole error max", "um", 1e6)
PORT_FORCE = SummaryMetric("port_force_max_n", "port_force_max_n", "port force max", "N")
EE_ERROR = SummaryMetric("ee_position_error_max_m", "ee_position_error_max_mm",
                         "EE position error max", "mm", 1e3)
FAILED_STEPS = SummaryMetric("failed_steps", "failed_steps", "failed steps", "", summed=True)
STEP_TIME = SummaryMetric("step_time_median_us", "step_time_median_us", "step time median",
                          "us")

#: The summary's metrics, in the order of its table and figures.
SUMMARY_METRICS = (HOLE_ERROR, PORT_FORCE, EE_ERROR, FAILED_STEPS, STEP_TIME)

#: The metrics ``teleop sweep show`` adds to those.
DETAIL_METRICS = (
    SummaryMetric("constraint_error_max_m", "constraint_error_max_m", "constraint error max",
                  "m"),
    SummaryMetric("ee_orientation_error_max_rad", "ee_orientation_error_max_mrad",
                  "EE orientation error max", "mrad", 1e3),
)


def controller_order(rows: Sequence[CellRow], listed: Sequence[str] = ()) -> list[str]:
    """The controllers of ``rows``: those of ``listed`` first in its order, then the others
    as first seen."""
    seen = list(dict.fromkeys([*listed, *(row.inputs["controller"] for row in rows)]))
    present = {row.inputs["controller"] for row in rows}
    return [name for name in seen if name in present]


def metric_values(rows: Sequence[CellRow], metric: SummaryMetric,
                  controllers: Sequence[str] = ()) -> dict[str, list[float]]:
    """Each controller's values of ``metric`` over its done cells that have one."""
    values: dict[str, list[float]] = {name: [] for name in controller_order(rows, controllers)}
    for row in rows:
        value = metric.value(row)
        if value is not None:
            values[row.inputs["controller"]].append(value)
    return values


def statistics(rows: list[CellRow], controllers: Sequence[str] = ()) -> dict[str, dict]:
    """Per controller (``controllers``' order, then as first seen): ``done`` and ``failed``
    cells, and for each of :data:`SUMMARY_METRICS` over the done cells having it, its
    ``cells``, ``median`` and ``worst`` (the largest) in the unit of its name, with
    ``total`` for failed steps; None where no done cell has it (no hole, no body)."""
    table: dict[str, dict] = {}
    for name in controller_order(rows, controllers):
        own = [row for row in rows if row.inputs["controller"] == name]
        done = sum(row.status == DONE for row in own)
        table[name] = {"done": done, "failed": len(own) - done}
    for metric in SUMMARY_METRICS:
        for name, values in metric_values(rows, metric, controllers).items():
            entry = None
            if values:
                entry = {"cells": len(values), "median": float(np.median(values)),
                         "worst": float(np.max(values))}
                if metric.summed:
                    entry["total"] = float(np.sum(values))
            table[name][metric.name] = entry
    return table


def _g(value: float | None) -> str:
    return "-" if value is None else f"{value:.3g}"


def statistics_columns(table: Mapping[str, dict]) -> tuple[list[str], list[list[str]]]:
    """The statistics as a header and one row of text cells per controller; a metric no
    controller has (no hole, no body) has no columns."""
    headers = ["controller", "cells done", "failed"]
    shown = [m for m in SUMMARY_METRICS if any(entry[m.name] for entry in table.values())]
    for metric in shown:
        first = "total" if metric.summed else "median"
        second = "worst cell" if metric.summed else "worst"
        headers += [f"{metric.heading} {first}", second]
    lines = []
    for name, entry in table.items():
        cells = [name, str(entry["done"]), str(entry["failed"])]
        for metric in shown:
            stats = entry[metric.name] or {}
            cells += [_g(stats.get("total" if metric.summed else "median")),
                      _g(stats.get("worst"))]
        lines.append(cells)
    return headers, lines


def format_statistics(table: Mapping[str, dict]) -> str:
    """The statistics as a Markdown table (the medians and worsts over each controller's
    done cells)."""
    headers, lines = statistics_columns(table)
    return "\n".join("| " + " | ".join(cells) + " |"
                     for cells in [headers, ["---"] * len(headers), *lines])


def worst_rows(rows: Sequence[CellRow]) -> list[CellRow]:
    """The cells, worst first: the failed ones (as they finished), then the done ones by
    failed steps, hole error and EE error, each largest first."""
    def badness(row: CellRow) -> tuple:
        if row.status != DONE:
            return (0,)
        return (1, *(-value if value is not None else math.inf
                     for value in (metric.value(row)
                                   for metric in (FAILED_STEPS, HOLE_ERROR, EE_ERROR))))
    return sorted(rows, key=badness)


def outcome_line(row: CellRow) -> str:
    """A cell's outcome in one line: why it failed, else its main metrics."""
    if row.status != DONE:
        return f"failed: {row.reason or 'no reason recorded'}"
    shown = [f"{metric.heading} {_g(metric.value(row))}" for metric in SUMMARY_METRICS
             if metric.value(row) is not None and metric is not STEP_TIME]
    return ", ".join(shown)


def ordered_inputs(inputs: Mapping[str, Any]) -> dict[str, Any]:
    """A cell's inputs in the order of the spec's fields (the database keeps them sorted)."""
    return {f.name: inputs[f.name] for f in CELL_FIELDS if f.name in inputs}


def report_command(key: str, folder: Path) -> str:
    """The command that makes a cell's report into the sweep's folder."""
    return shlex.join(["teleop", "sweep", "report", key, "--out", str(folder)])


def show_command(key: str, folder: Path) -> str:
    """The command that describes a cell of the sweep's folder."""
    return shlex.join(["teleop", "sweep", "show", key, "--out", str(folder)])


def format_worst(rows: Sequence[CellRow], folder: Path, report_links: Mapping[str, str],
                 listed: int = WORST_LISTED) -> str:
    """The worst cells (:func:`worst_rows`), one paragraph each: key, description,
    outcome, and the report made or the command that makes it."""
    worst = worst_rows(rows)
    lines = []
    for row in worst[:listed]:
        where = (str(folder / report_links[row.key]) if row.key in report_links
                 else report_command(row.key, folder))
        lines += [f"{row.key}  {describe_cell(ordered_inputs(row.inputs))}",
                  f"    {outcome_line(row)}", f"    report: {where}"]
    if len(worst) > listed:
        lines.append(f"({len(worst) - listed} more cells; {show_command('KEY', folder)} "
                     "describes any)")
    return "\n".join(lines)


STYLE = """
body { font-family: sans-serif; margin: 2em; max-width: 1400px; color: #222; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #bbb; padding: 0.3em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
td.text { text-align: left; }
td.failed { color: #a00; }
code { font-size: 0.95em; }
figure { margin: 2em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #444; margin-top: 0.4em; }
.note { font-size: 0.9em; color: #444; }
"""


def _statistics_html(table: Mapping[str, dict]) -> str:
    e = html.escape
    headers, lines = statistics_columns(table)
    head = "<tr>" + "".join(f"<th>{e(text)}</th>" for text in headers) + "</tr>"
    body = "".join("<tr>" + "".join(f"<td>{e(text)}</td>" for text in cells) + "</tr>"
                   for cells in lines)
    return f"<table>{head}{body}</table>"


def _figures_html(rows: Sequence[CellRow], controllers: Sequence[str]) -> list[str]:
    from .summary_plots import box_plot

    parts = []
    for metric in SUMMARY_METRICS:
        values = metric_values(rows, metric, controllers)
        if not any(values.values()):
            continue
        title = f"{metric.label}, each done cell"
        png = box_plot(values, title, metric.heading, integer=metric.summed)
        data = base64.b64encode(png).decode("ascii")
        parts.append(
            f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(title)}">'
            f"<figcaption>{html.escape(title)}: the box spans the quartiles, its red line "
            "is the median, the whiskers reach the farthest cell within 1.5 times the "
            "box; each dot is a cell.</figcaption></figure>")
    return parts


def _worst_html(rows: Sequence[CellRow], folder: Path, report_links: Mapping[str, str],
                listed: int = WORST_LISTED) -> str:
    e = html.escape
    worst = worst_rows(rows)
    parts = ["<table><tr><th>key</th><th>cell</th><th>outcome</th><th>report</th></tr>"]
    for row in worst[:listed]:
        if row.key in report_links:
            report = f'<a href="{e(report_links[row.key])}">report.html</a>'
        else:
            report = f"<code>{e(report_command(row.key, folder))}</code>"
        kind = "text" if row.status == DONE else "text failed"
        parts.append(f'<tr><td><code>{e(row.key)}</code></td>'
                     f'<td class="text">{e(describe_cell(ordered_inputs(row.inputs)))}</td>'
                     f'<td class="{kind}">{e(outcome_line(row))}</td>'
                     f'<td class="text">{report}</td></tr>')
    parts.append("</table>")
    if len(worst) > listed:
        parts.append(f'<p class="note">{len(worst) - listed} more cells: '
                     f"<code>{e(show_command('KEY', folder))}</code> describes any.</p>")
    return "".join(parts)


def write_summary(rows: list[CellRow], folder: Path, report_links: dict[str, str],
                  controllers: Sequence[str] = ()) -> Path:
    """Write ``folder/summary.html``: the statistics, a box plot per metric, the worst
    cells with their reports (``report_links``: key -> path relative to ``folder``) or the
    command that makes them; returns its path."""
    e = html.escape
    folder = Path(folder)
    done = sum(row.status == DONE for row in rows)
    versions = sorted({row.version or "unknown" for row in rows})
    parts = [
        "<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
        "<title>teleop sweep: summary</title>", f"<style>{STYLE}</style>", "</head>",
        "<body>", "<h1>Sweep summary</h1>",
        f"<p>{len(rows)} cells: {done} done, {len(rows) - done} failed; package version "
        f"{e(', '.join(versions) or '-')}; folder <code>{e(str(folder))}</code>.</p>",
        "<h2>Each controller over its cells</h2>", _statistics_html(statistics(rows, controllers)),
        '<p class="note">Median and worst (the largest) over each controller\'s done cells '
        "that have the metric: hole error on the true configuration (scenarios with a "
        "hole), port force on a plant with a body (mujoco); failed steps: the total over "
        "the cells and the worst cell's.</p>",
        "<h2>Distributions</h2>", *_figures_html(rows, controllers),
        "<h2>The worst cells</h2>",
        '<p class="note">Failed cells first, then the done cells by failed steps, hole '
        "error and EE error, largest first.</p>",
        _worst_html(rows, folder, report_links), "</body>", "</html>",
    ]
    path = folder / SUMMARY_NAME
    path.write_text("\n".join(parts) + "\n", encoding="utf-8")
    return path


def _last_line(text: str) -> str:
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    return lines[-1] if lines else "no output"


def make_report(row: CellRow, folder: Path, timeout: float | None = None) -> Path:
    """Make the cell's own ``teleop compare`` report into ``folder/reports/KEY/`` by its
    command (:func:`compare_command`) in a subprocess of this package, stopped after
    ``timeout`` s (None: :data:`DEFAULT_TIME_LIMIT_S`); the path of its report.html.
    ``ValueError`` naming the key and the command's last error line when it fails or
    times out."""
    import teleop

    out = (Path(folder) / REPORTS_FOLDER / row.key).resolve()
    words = shlex.split(compare_command(row.inputs, out=str(out)))[1:]
    root = Path(teleop.__file__).resolve().parent.parent  # the same package as this one
    limit = DEFAULT_TIME_LIMIT_S if timeout is None else timeout
    try:
        done = subprocess.run([sys.executable, "-m", "teleop", *words, "--quiet"],
                              cwd=root, stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=limit)
    except subprocess.TimeoutExpired:
        raise ValueError(f"the report of cell {row.key} timed out after {limit:g} s") from None
    if done.returncode != 0:
        raise ValueError(f"the report of cell {row.key} failed (exit {done.returncode}): "
                         f"{_last_line(done.stderr)}")
    report = out / "report.html"
    if not report.is_file():
        raise ValueError(f"the report of cell {row.key} wrote no {report}")
    return report


def describe_row(row: CellRow) -> str:
    """A cell for ``teleop sweep show``: its key, inputs, outcome, main metrics, run and
    the ``teleop compare`` command that redoes it."""
    inputs = ordered_inputs(row.inputs)
    lines = [f"cell {row.key}: {describe_cell(inputs)}", "inputs (the others at their "
             "defaults):"]
    lines += [f"  {name}: {value}" for name, value in inputs.items()]
    lines.append(f"status: {row.status}")
    if row.status != DONE:
        lines.append(f"reason: {row.reason or 'no reason recorded'}")
    metrics = row.metrics or {}
    if metrics:
        lines.append("metrics:")
    for metric in (*SUMMARY_METRICS, *DETAIL_METRICS):
        if metrics.get(metric.key) is not None:
            lines.append(f"  {metric.heading}: {_g(float(metrics[metric.key]) * metric.scale)}")
    if metrics.get("first_failure"):
        lines.append(f"  first failed step: {metrics['first_failure']}")
    finished = datetime.datetime.fromtimestamp(row.finished_at).isoformat(timespec="seconds")
    elapsed = "-" if row.elapsed_s is None else f"{row.elapsed_s:.2f} s"
    lines += [f"elapsed: {elapsed}, attempts: {row.attempts}, finished {finished}",
              f"worker: {row.worker or '-'}, version: {row.version or 'unknown'}",
              f"redo: {compare_command(inputs)}"]
    return "\n".join(lines)


def finish_sweep(spec: SweepSpec, folder: Path, reports: int) -> str:
    """After a run: the rows of the spec's cells, the reports of the ``reports`` worst
    done cells (a failed report is told, not raised), summary.html; the text to print."""
    if isinstance(reports, bool) or not isinstance(reports, int) or reports < 0:
        raise ValueError(f"reports must be an integer >= 0, got {reports!r}")
    folder = Path(folder)
    controllers = spec.grid["controller"]
    with ResultsDatabase(folder / DATABASE_NAME) as database:
        rows = database.rows({cell.key for cell in spec.cells()})
        versions = database.versions()
    links: dict[str, str] = {}
    problems = []
    for row in [row for row in worst_rows(rows) if row.status == DONE][:reports]:
        try:
            report = make_report(row, folder, spec.time_limit + REPORT_MARGIN_S)
        except ValueError as error:
            problems.append(f"note: {error}")
            continue
        links[row.key] = report.relative_to(folder.resolve()).as_posix()
    path = write_summary(rows, folder, links, controllers)
    text = [format_statistics(statistics(rows, controllers)), "", "worst cells:",
            format_worst(rows, folder, links, WORST_PRINTED) or "(none)", *problems,
            f"wrote {path}"]
    if len(versions) > 1:
        text.append(f"note: the database holds cells of {len(versions)} package versions "
                    f"({', '.join(versions)}); teleop sweep show KEY tells a cell's")
    return "\n".join(text)
