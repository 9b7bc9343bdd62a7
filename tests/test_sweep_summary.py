"""The end of a sweep (docs/sweep.md): the statistics over real cells against NumPy, the
summary page (parsed: self-contained, escaped, a figure per metric, the worst cells in
order), a cell's compare report against its row, and ``teleop sweep show``'s text.

The cells are real ``run_plan`` runs written to a real results database; a failed cell is
written as the driver would write one (its reason holds markup, which must stay text)."""

from __future__ import annotations

import base64
import json
import math
import shlex
import time
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from teleop.cli.main import build_parser
from teleop.experiments.compare import run_plan
from teleop.experiments.scenarios import load_scenario
from teleop.experiments.solver_output import SolverOutputCapture
from teleop.experiments.sweep.cell import compare_command
from teleop.experiments.sweep.database import DATABASE_NAME, CellRow, ResultsDatabase
from teleop.experiments.sweep.spec import Cell, build_spec
from teleop.experiments.sweep.summary import (
    SUMMARY_NAME,
    describe_row,
    finish_sweep,
    format_statistics,
    format_worst,
    make_report,
    statistics,
    worst_rows,
    write_summary,
)
from teleop.experiments.sweep.summary_plots import LOG_SPAN, axis_scale
from teleop.loop import LoopConfig, StateObserverConfig
from teleop.plants.choice import PlantChoice
from teleop.plants.imperfect import Imperfections

#: A failed cell's reason with markup in it: the page must show it as text.
HOSTILE = "RuntimeError: <script>alert('x')</script> & <img src=http://evil.example/x.png>"

#: The keys of a controller's metrics that do not depend on the wall clock.
DETERMINISTIC = ("constraint_error_max_m", "constraint_error_rms_m", "hole_error_max_m",
                 "ee_position_error_max_m", "ee_position_error_rms_m",
                 "ee_orientation_error_max_rad", "failed_steps", "end_effectors",
                 "constraints")

#: The grid most tests summarise: two scenarios (one without a hole), two controllers (the
#: spec lists qp:osqp first), two noisy seeds.
GRID = {"scenarios": ["paper-hole", "paper-plane"], "controllers": ["qp:osqp", "cjm"],
        "seeds": [1, 2], "duration": 0.5, "encoder_noise": 1e-4}

#: Cells beside the grid: one with failed steps (mink's proxqp at its iteration cap under
#: heavy noise, without acceleration limits: their box keeps it within its cap; the QP's
#: OSQP, which failed there, now finishes such stages, docs/design.md 18.7), a CJM one under
#: heavier noise (a larger hole error, no failed step), one on the physics plant (port
#: forces), all of another version. The two noisy ones run on the encoders raw (RAW): the
#: loop's state observer (docs/design.md 5.6) filters such noise, and OSQP no longer fails.
EXTRA = [
    {"scenario": "multi", "controller": "mink:proxqp", "seed": 1, "encoder_noise": 0.05,
     "duration": 0.5, "acceleration_limits": False},
    {"scenario": "multi", "controller": "cjm", "seed": 1, "encoder_noise": 0.1,
     "duration": 0.5},
    {"scenario": "trocar-circle", "controller": "cjm", "plant": "mujoco", "duration": 0.3},
]
RAW = LoopConfig(state_observer=StateObserverConfig(enabled=False))


def run_and_write(database: ResultsDatabase, cell: Cell, version: str = "0.1.0",
                  config: LoopConfig | None = None) -> None:
    """Run the cell as ``run_cell`` does (its scenario, controller, noise and seed, plant;
    the solvers' output kept; the loop's ``config``, default its own) and write its done
    outcome."""
    started = time.monotonic()
    with SolverOutputCapture() as capture:
        result = run_plan(load_scenario(cell["scenario"]), cell["controller"],
                          config or LoopConfig(),
                          cell["duration"], imperfections=Imperfections(
                              cell["encoder_noise"], cell["latency"],
                              cell["joint_time_constant"], cell["seed"]),
                          plant=PlantChoice(cell["plant"]),
                          acceleration_limits=cell["acceleration_limits"])
        result.solver_messages = capture.collect()
    outcome = {"status": "done", "reason": None, "metrics": result.metrics(),
               "elapsed_s": time.monotonic() - started, "worker": "test:1", "version": version}
    assert database.write(cell.key, cell.inputs, outcome, attempts=1)


def write_failed(database: ResultsDatabase, cell: Cell, reason: str) -> None:
    outcome = {"status": "failed", "reason": reason, "metrics": None, "elapsed_s": 0.2,
               "worker": "test:2", "version": "0.1.0"}
    assert database.write(cell.key, cell.inputs, outcome, attempts=3)


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """A sweep folder: the grid's cells, the extra cells and a failed one; its rows."""
    folder = tmp_path_factory.mktemp("sweep")
    spec = build_spec(GRID)
    failed = Cell.of({"scenario": "paper-hole", "controller": "cjm", "seed": 9,
                      "encoder_noise": 1e-4})
    with ResultsDatabase(folder / DATABASE_NAME) as database:
        for cell in spec.cells():
            run_and_write(database, cell)
        for values in EXTRA:
            run_and_write(database, Cell.of(values), version="0.0.9",
                          config=RAW if values.get("encoder_noise") else None)
        write_failed(database, failed, HOSTILE)
        rows = database.rows()
    return folder, spec, rows, failed.key


def expected_statistics(rows: list[CellRow], controller: str) -> dict:
    """The statistics of one controller, from its rows' metrics with NumPy."""
    own = [row for row in rows if row.inputs["controller"] == controller]
    done = [row.metrics for row in own if row.status == "done"]

    def stats(key: str, scale: float) -> dict | None:
        values = np.array([m[key] * scale for m in done if m[key] is not None], dtype=float)
        if values.size == 0:
            return None
        return {"cells": values.size, "median": np.median(values), "worst": values.max()}

    failed_steps = stats("failed_steps", 1.0)
    failed_steps["total"] = float(sum(m["failed_steps"] for m in done))
    return {"done": len(done), "failed": len(own) - len(done),
            "hole_error_max_um": stats("hole_error_max_m", 1e6),
            "ee_position_error_max_mm": stats("ee_position_error_max_m", 1e3),
            "port_force_max_n": stats("port_force_max_n", 1.0),
            "failed_steps": failed_steps,
            "step_time_median_us": stats("step_time_median_us", 1.0)}


def test_the_statistics_are_numpys_over_each_controllers_done_cells(sweep):
    _, _, rows, _ = sweep
    table = statistics(rows, ["cjm", "qp:osqp", "mink:proxqp"])
    assert list(table) == ["cjm", "qp:osqp", "mink:proxqp"]
    assert list(statistics(rows)) == list(dict.fromkeys(r.inputs["controller"] for r in rows))
    for controller in ("cjm", "qp:osqp", "mink:proxqp"):
        expected = expected_statistics(rows, controller)
        assert set(table[controller]) == set(expected)
        for name, value in expected.items():
            if isinstance(value, dict):
                assert table[controller][name] == pytest.approx(value, rel=1e-12), name
            else:
                assert table[controller][name] == value, name
    # the holes: the paper-plane cells have none; the port force: cjm's mujoco cell only
    assert table["cjm"]["hole_error_max_um"]["cells"] == 2 + 1 + 1
    assert table["cjm"]["port_force_max_n"]["cells"] == 1
    assert table["qp:osqp"]["port_force_max_n"] is None
    assert table["mink:proxqp"]["failed_steps"]["total"] > 0
    assert (table["cjm"]["done"], table["cjm"]["failed"]) == (4 + 2, 1)


def test_the_text_table_shows_the_statistics(sweep):
    _, _, rows, _ = sweep
    table = statistics(rows, ["cjm", "qp:osqp", "mink:proxqp"])
    lines = format_statistics(table).splitlines()
    headers = [cell.strip() for cell in lines[0].strip("|").split("|")]
    assert headers[:3] == ["controller", "cells done", "failed"]
    assert lines[1].count("---") == len(headers)
    shown = {cells[0]: cells for cells in ([c.strip() for c in line.strip("|").split("|")]
                                          for line in lines[2:])}
    assert list(shown) == ["cjm", "qp:osqp", "mink:proxqp"]
    columns = {"hole error max (um) median": "hole_error_max_um",
               "port force max (N) median": "port_force_max_n",
               "EE position error max (mm) median": "ee_position_error_max_mm",
               "failed steps total": "failed_steps",
               "step time median (us) median": "step_time_median_us"}
    for controller, cells in shown.items():
        assert cells[1:3] == [str(table[controller]["done"]), str(table[controller]["failed"])]
        for heading, name in columns.items():
            column = headers.index(heading)
            stats = table[controller][name]
            first = "total" if name == "failed_steps" else "median"
            assert cells[column:column + 2] == (["-", "-"] if stats is None else [
                f"{stats[first]:.3g}", f"{stats['worst']:.3g}"]), (controller, heading)
    assert shown["qp:osqp"][headers.index("port force max (N) median")] == "-"


def expected_worst(rows: list[CellRow]) -> list[str]:
    """Failed first as they finished, then done by failed steps, hole, EE error (largest
    first; no hole after any hole)."""
    failed = [row.key for row in rows if row.status != "done"]
    done = [row for row in rows if row.status == "done"]
    done.sort(key=lambda row: (row.metrics["failed_steps"],
                               -math.inf if row.metrics["hole_error_max_m"] is None
                               else row.metrics["hole_error_max_m"],
                               row.metrics["ee_position_error_max_m"]), reverse=True)
    return failed + [row.key for row in done]


def test_the_worst_cells_are_the_failed_then_by_failed_steps_hole_and_ee_error(sweep):
    _, _, rows, failed_key = sweep
    order = [row.key for row in worst_rows(rows)]
    assert order == expected_worst(rows)
    assert order[0] == failed_key
    second = next(row for row in rows if row.key == order[1])
    assert second.metrics["failed_steps"] > 0
    assert second.inputs["scenario"] == "multi"
    # the failed steps outrank a larger hole error
    assert max(row.metrics["hole_error_max_m"] or 0 for row in rows if row.status == "done"
               ) > second.metrics["hole_error_max_m"]
    last = next(row for row in rows if row.key == order[-1])
    assert last.metrics["hole_error_max_m"] is None  # a paper-plane cell


class Page(HTMLParser):
    """What the summary page holds: its tags, their URLs, its text, the worst cells' keys."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.sources: list[str] = []
        self.alts: list[str] = []
        self.links: list[str] = []
        self.text: list[str] = []
        self.codes: list[str] = []
        self._in_code = False

    def handle_starttag(self, tag, attrs):
        self.tags.append(tag)
        values = dict(attrs)
        if "src" in values:
            self.sources.append(values["src"])
            self.alts.append(values.get("alt", ""))
        if "href" in values:
            self.links.append(values["href"])
        self._in_code = tag == "code"

    def handle_endtag(self, tag):
        self._in_code = False

    def handle_data(self, data):
        self.text.append(data)
        if self._in_code:
            self.codes.append(data)


def parse(path: Path) -> Page:
    page = Page()
    page.feed(path.read_text(encoding="utf-8"))
    page.close()
    return page


def test_the_summary_is_self_contained_escaped_and_has_a_figure_per_metric(sweep, tmp_path):
    _, _, rows, failed_key = sweep
    linked = worst_rows(rows)[1].key
    links = {linked: f"reports/{linked}/report.html"}
    path = write_summary(rows, tmp_path, links, ["cjm", "qp:osqp"])
    assert path == tmp_path / SUMMARY_NAME
    page = parse(path)
    assert "script" not in page.tags and "link" not in page.tags
    assert HOSTILE in "".join(page.text)  # the markup came back as text
    raw = path.read_text(encoding="utf-8")
    assert "url(" not in raw and "@import" not in raw
    assert page.links == [f"reports/{linked}/report.html"]
    assert [alt.split(",")[0] for alt in page.alts] == [
        "hole error max", "port force max", "EE position error max", "failed steps",
        "step time median"]
    for source in page.sources:
        prefix = "data:image/png;base64,"
        assert source.startswith(prefix)
        assert base64.b64decode(source[len(prefix):]).startswith(b"\x89PNG\r\n\x1a\n")
    keys = [text for text in page.codes if text in {row.key for row in rows}]
    assert keys == expected_worst(rows)[:len(keys)] and keys[0] == failed_key
    assert len(keys) == min(20, len(rows))
    assert f"teleop sweep report {failed_key} --out {tmp_path}" in page.codes


def test_a_kinematic_sweep_without_holes_has_no_port_force_or_hole_figure(sweep, tmp_path):
    _, _, rows, _ = sweep
    planes = [row for row in rows if row.inputs["scenario"] == "paper-plane"]
    page = parse(write_summary(planes, tmp_path, {}))
    assert page.alts == ["EE position error max, each done cell",
                         "failed steps, each done cell", "step time median, each done cell"]


def test_the_worst_cells_text_shows_the_reason_and_the_report_command(sweep):
    folder, _, rows, failed_key = sweep
    text = format_worst(rows, folder, {})
    first = text.splitlines()[:3]
    assert first == [f"{failed_key}  paper-hole / cjm / seed 9 (encoder_noise 0.0001)",
                     f"    failed: {HOSTILE}",
                     f"    report: teleop sweep report {failed_key} --out {folder}"]


def test_describe_row_tells_the_cell_and_the_command_that_redoes_it(sweep):
    _, _, rows, failed_key = sweep
    done = worst_rows(rows)[1]
    text = describe_row(done)
    lines = text.splitlines()
    assert lines[0] == f"cell {done.key}: multi / mink:proxqp / seed 1 (duration 0.5, " \
        "acceleration_limits False, encoder_noise 0.05)"
    assert lines[1:8] == ["inputs (the others at their defaults):", "  scenario: multi",
                          "  controller: mink:proxqp", "  seed: 1", "  duration: 0.5",
                          "  acceleration_limits: False", "  encoder_noise: 0.05"]
    assert "status: done" in lines
    assert f"  failed steps: {done.metrics['failed_steps']:.3g}" in lines
    assert f"  hole error max (um): {done.metrics['hole_error_max_m'] * 1e6:.3g}" in lines
    assert f"attempts: {done.attempts}" in text and f"version: {done.version}" in text
    command = lines[-1].removeprefix("redo: ")
    assert command == compare_command({name: done.inputs[name] for name in (
        "scenario", "controller", "seed", "duration", "acceleration_limits", "encoder_noise")})
    assert "--no-acceleration-limits" in shlex.split(command)
    args = build_parser().parse_args(shlex.split(command)[1:])
    assert (args.scenario, args.controllers, args.seed, args.encoder_noise, args.duration) == (
        "multi", ["mink:proxqp"], 1, 0.05, 0.5)
    failed = describe_row(next(row for row in rows if row.key == failed_key))
    assert f"reason: {HOSTILE}" in failed.splitlines() and "status: failed" in failed


def test_a_cells_report_has_the_rows_metrics(tmp_path):
    cell = Cell.of({"scenario": "paper-hole", "controller": "cjm", "duration": 0.5})
    with ResultsDatabase(tmp_path / DATABASE_NAME) as database:
        run_and_write(database, cell)
        row = database.row(cell.key)
    report = make_report(row, tmp_path, timeout=300)
    assert report == (tmp_path / "reports" / cell.key / "report.html").resolve()
    assert report.is_file()
    document = json.loads((report.parent / "metrics.json").read_text())
    assert document["duration_s"] == 0.5
    metrics = document["controllers"]["cjm"]
    for key in DETERMINISTIC:
        assert metrics[key] == row.metrics[key], key


def test_a_report_the_compare_command_refuses_names_the_key(tmp_path):
    cell = Cell.of({"scenario": "no-such-scenario", "controller": "cjm", "duration": 0.5})
    with ResultsDatabase(tmp_path / DATABASE_NAME) as database:
        write_failed(database, cell, "ValueError: unknown scenario 'no-such-scenario'")
        row = database.row(cell.key)
    with pytest.raises(ValueError, match=rf"cell {cell.key}.*unknown scenario "
                                         r"'no-such-scenario'"):
        make_report(row, tmp_path, timeout=300)


def test_finish_sweep_reports_the_worst_done_cell_of_the_spec(sweep):
    folder, spec, rows, failed_key = sweep
    text = finish_sweep(spec, folder, reports=1)
    own = [row for row in rows if row.key in {cell.key for cell in spec.cells()}]
    worst = worst_rows(own)[0]
    link = f"reports/{worst.key}/report.html"
    assert (folder / link).is_file()
    assert text.startswith(format_statistics(statistics(own, spec.grid["controller"])))
    assert f"report: {folder / link}" in text
    assert f"wrote {folder / SUMMARY_NAME}" in text
    assert "2 package versions (0.0.9, 0.1.0)" in text.splitlines()[-1]
    for other in (failed_key, *(Cell.of(values).key for values in EXTRA)):
        assert other not in text
    page = parse(folder / SUMMARY_NAME)
    assert page.links == [link]
    with pytest.raises(ValueError, match="reports"):
        finish_sweep(spec, folder, reports=-1)


@given(st.lists(st.floats(1e-12, 1e12), min_size=2, max_size=20), st.booleans())
def test_the_axis_is_logarithmic_where_the_values_span_two_decades(values, with_zero):
    data = values + [0.0] if with_zero else values
    scale, threshold = axis_scale(data)
    spans = max(values) >= LOG_SPAN * min(values)
    assert scale == ("linear" if not spans else "symlog" if with_zero else "log")
    assert threshold == (min(values) if scale == "symlog" else None)


def test_a_report_past_its_timeout_names_the_key(tmp_path):
    cell = Cell.of({"scenario": "paper-hole", "controller": "cjm", "duration": 0.5})
    with ResultsDatabase(tmp_path / DATABASE_NAME) as database:
        run_and_write(database, cell)
        row = database.row(cell.key)
    # a millisecond: less than the interpreter takes to start
    with pytest.raises(ValueError, match=rf"cell {cell.key} timed out after 0.001 s"):
        make_report(row, tmp_path, timeout=0.001)
