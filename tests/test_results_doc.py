"""docs/results.md is generated (docs/make_results.py) from ``teleop bench --json`` and
``teleop compare`` output: a table rendered from a small real run carries that run's numbers,
the committed document is what the script renders from the committed raw outputs, and the
README's headline table is the document's."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "docs" / "make_results.py"


def load_script():
    spec = importlib.util.spec_from_file_location("make_results", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look themselves up there
    spec.loader.exec_module(module)
    return module


make_results = load_script()


def teleop(*args: str) -> None:
    result = subprocess.run([sys.executable, "-m", "teleop.cli", *args], capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0, result.stderr


def table(lines: list[str], first_header: str) -> list[dict[str, str]]:
    """The Markdown table whose first header is ``first_header``, as one dict per row."""
    start = next(i for i, line in enumerate(lines) if line.startswith(f"| {first_header} |"))
    headers = [cell.strip() for cell in lines[start].strip("|").split("|")]
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append(dict(zip(headers, (cell.strip() for cell in line.strip("|").split("|")))))
    return rows


@pytest.fixture(scope="module")
def small_run(tmp_path_factory) -> Path:
    """A real bench (two robots, three controllers, 20 iterations) and a real comparison
    (20 steps of paper-hole), laid out as ``run`` keeps them."""
    raw = tmp_path_factory.mktemp("raw")
    (raw / "compare").mkdir()
    teleop("bench", "--quick", "--no-scaling", "--robots", "sda10f,sda10f_dual",
           "--controllers", "cjm,qp:daqp,mink:daqp", "--json", str(raw / "bench.json"))
    out = raw / "out"
    teleop("compare", "--scenario", "paper-hole", "--duration", "0.02", "--controllers",
           "cjm,qp:daqp", "--out", str(out), "--no-plots", "--quiet")
    (raw / "compare" / "paper-hole.json").write_text((out / "metrics.json").read_text())
    runs = {"date": "2026-01-01", "machine": make_results.machine(), "bench": "teleop bench ...",
            "comparisons": {"paper-hole": "teleop compare --scenario paper-hole ..."}}
    (raw / "runs.json").write_text(json.dumps(runs))
    return raw


def test_the_tables_carry_the_numbers_of_the_run(small_run):
    lines = make_results.render(small_run).splitlines()
    bench = json.loads((small_run / "bench.json").read_text())
    document = json.loads((small_run / "compare" / "paper-hole.json").read_text())
    metrics = document["controllers"]

    headline = {row["controller"]: row for row in table(lines, "controller")}
    assert set(headline) == {"`cjm`", "`qp:daqp`"}
    for spec in metrics:
        row = headline[f"`{spec}`"]
        error = float(row["constraint error max (m), 1 scenarios"])
        assert error == pytest.approx(metrics[spec]["constraint_error_max_m"], rel=0.06)
        assert int(row["failed steps"]) == metrics[spec]["failed_steps"]
        for robot in ("sda10f", "sda10f_dual"):
            (median,) = [r["median_us"] for r in bench
                         if r["robot"] == robot and r["controller"] == spec]
            shown = float(row[f"one step, {robot} (us)"])
            assert abs(shown - median) <= (0.5 if median >= 100 else 0.05), (robot, spec)

    timings = table(lines, "problem")
    # the two robots' holes, then the dual robot's arms close without and with collision
    # avoidance (sda10f_dual/close, sda10f_dual/collisions): four problems, three controllers
    assert len(timings) == len(bench) == 12
    for row, timing in zip(timings, bench):
        assert row["problem"] == timing["robot"]
        assert row["controller"] == f"`{timing['controller']}`"
        assert int(row["DoF"]) == timing["dof"] and int(row["rows"]) == timing["constraint_rows"]
        assert abs(float(row["median us"]) - timing["median_us"]) <= 0.5
    (scenario,) = table(lines, "scenario")[:1]
    assert scenario["scenario"] == "paper-hole"
    assert float(scenario["`cjm`"]) == pytest.approx(metrics["cjm"]["constraint_error_max_m"],
                                                     rel=0.06)
    assert "* **Date:** 2026-01-01." in lines
    assert "20 steps" in "\n".join(lines)


def test_the_committed_document_is_what_the_script_renders():
    committed = (ROOT / "docs" / "results.md").read_text(encoding="utf-8")
    assert committed == make_results.render(make_results.RAW), (
        "docs/results.md differs from its raw outputs: python docs/make_results.py render")


def test_the_readme_headline_table_is_the_documents():
    lines = make_results.render(make_results.RAW).splitlines()
    start = lines.index("## Headline") + 2
    end = lines.index("", start)
    headline = "\n".join(lines[start:end])
    assert headline in (ROOT / "README.md").read_text(encoding="utf-8")
