"""docs/results.md, generated from measurements: ``teleop compare`` and ``teleop bench``.

    python docs/make_results.py run      # run every measurement (about half an hour on 2
                                         # cores), keep its raw output in docs/results/,
                                         # then write docs/results.md
    python docs/make_results.py render   # docs/results.md again from docs/results/

``run`` calls the ``teleop`` command line of the installed package, one process at a time,
each command written down with the date and the machine in ``docs/results/runs.json``;
what each run printed is not needed: ``metrics.json`` of every comparison and the JSON of
the bench are kept, the figures of the paper's Fig 3 copied into docs/. ``render`` only
reads those files: every number of docs/results.md comes from them, none is typed.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Sequence

from teleop.experiments.metrics_table import format_status_counts, table_cells, table_headers

DOCS = Path(__file__).resolve().parent
#: where ``run`` keeps the raw outputs that ``render`` reads
RAW = DOCS / "results"
RESULTS = DOCS / "results.md"
#: the controllers of the comparisons (``teleop compare``'s default list)
FIVE = "cjm,qp:proxqp,qp:daqp,qp:osqp,mink:daqp"
#: the scenarios of the headline comparison, in order (10 s at 1 kHz each)
SCENARIOS = ("paper-hole", "paper-plane", "trocar-circle", "insertion", "moving-trocar",
             "near-singular", "joint-limits", "barrier", "multi")
#: the distributions whose versions results.md states
PACKAGES = ("cjm-teleop", "pin", "numpy", "qpsolvers", "proxsuite", "daqp", "osqp", "mink")
#: one control step of each controller: iterations per problem
BENCH_ITERATIONS = 1000


@dataclass(frozen=True)
class Run:
    """One comparison: its name in docs/results/ and the arguments of ``teleop compare``."""

    name: str
    arguments: tuple[str, ...]
    #: copy its constraint_velocity.png (the paper's Fig 3) to docs/ under this name
    figure: str | None = None

    def arguments_with(self, out: str) -> list[str]:
        """``teleop``'s arguments, writing to ``out``."""
        plots = () if self.figure else ("--no-plots",)
        return ["compare", *self.arguments, "--out", out, "--quiet", *plots]


COMPARISONS = (
    *(Run(name, ("--scenario", name, "--controllers", FIVE),
          "fig3_paper_hole.png" if name == "paper-hole" else None) for name in SCENARIOS),
    Run("paper-hole-noise-1e-4", ("--scenario", "paper-hole", "--controllers", "cjm",
                                  "--encoder-noise", "1e-4", "--seed", "0"),
        "fig3_paper_hole_noise_1e-4.png"),
    Run("bimanual-trocars", ("--scenario", "bimanual-trocars", "--controllers",
                             "cjm,cjm:general," + FIVE.partition(",")[2])),
    # without osqp: at the wall it runs every step to its iteration cap (the next run)
    Run("mobile-wall", ("--scenario", "mobile-wall", "--controllers",
                        "cjm,cjm:general,qp:proxqp,qp:daqp,mink:daqp")),
    Run("mobile-wall-osqp", ("--scenario", "mobile-wall", "--controllers", "cjm,qp:osqp",
                             "--duration", "4")),
)


#: What a comparison's numbers mean, where the table alone does not say it (no figures:
#: those come from the runs).
NOTES = {
    "moving-trocar": "The trocar itself moves: the errors are measured at the instant the "
                     "robot is at, so one period of the trocar's own motion is not counted "
                     "as the controllers' error.",
    "near-singular": "The CJM damps near the singularity (eq 35, `least_squares` steps) and "
                     "the QPs and mink carry the same damping; what is left of the "
                     "joint-velocity deviation is where the damping acts: the analytical CJM "
                     "damps its own variables `v_m`, the QP the general form's.",
    "joint-limits": "The target asks the wrist past its bound: every controller holds the "
                    "joint at it (`least_squares`); a distance past the limit of one ulp is "
                    "the integrator's rounding as the joint converges on its bound.",
    "multi": "A hole and a plane leave 5 free DoF for a 6-D task: `least_squares` by design.",
    "paper-hole-noise-1e-4": "The controllers see the noisy `q`; the errors are measured on "
                             "the true one.",
    "bimanual-trocars": "Two holes leave 11 of the 15 joint directions for 12 task entries; the "
                        "targets' orientations come from a kinematic reference run that holds "
                        "both holes, so both full poses are reachable.",
    "mobile-wall": "The EE errors are by design: the base stops at the wall (the barriers on "
                   "its front corners) and the targets go on out of reach. At the wall the QPs "
                   "and mink pick another least-squares command than the CJM's saturation in "
                   "the null space; all hold the barriers.",
    "mobile-wall-osqp": "OSQP at the wall: it runs each step to its iteration cap and fails "
                        "(the loop holds the robot still) where proxqp and daqp solve the same "
                        "problems. `compare` runs in simulated time, without a step deadline; "
                        "in a live loop the step's deadline is also OSQP's own time limit "
                        "(docs/design.md section 10.6).",
}


def processor() -> str:
    """The CPU's model name (Linux's /proc/cpuinfo), else what ``platform`` says."""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.startswith("model name"):
                return line.partition(":")[2].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def machine() -> dict:
    """What the measurements run on, and how busy it is (the 1-minute load average)."""
    versions = {}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return {"platform": platform.platform(), "processor": processor(),
            "cpus": os.cpu_count() or 0, "python": platform.python_version(),
            "load_average": round(os.getloadavg()[0], 2), "packages": versions}


def teleop(*arguments: str, env: dict[str, str]) -> None:
    """``teleop ARGUMENTS`` (this interpreter's package), its table not shown."""
    subprocess.run([sys.executable, "-m", "teleop.cli", *arguments], check=True, env=env,
                   stdout=subprocess.DEVNULL)


def run_all(raw: Path = RAW, docs: Path = DOCS, iterations: int = BENCH_ITERATIONS,
            comparisons: Sequence[Run] = COMPARISONS) -> dict:
    """Run the bench and every comparison, one after the other, keeping their raw output
    in ``raw`` (``runs.json``, ``bench.json``, ``compare/NAME.json``) and the Fig 3
    figures in ``docs``; returns what ``runs.json`` holds."""
    (raw / "compare").mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")  # one thread: no oversubscription
    runs = {"date": datetime.date.today().isoformat(), "machine": machine(),
            "bench": "", "comparisons": {}}
    loads = [runs["machine"]["load_average"]]
    bench = ["bench", "--iterations", str(iterations), "--json"]
    teleop(*bench, str(raw / "bench.json"), env=env)
    runs["bench"] = " ".join(["OPENBLAS_NUM_THREADS=1 teleop", *bench, "bench.json"])
    with tempfile.TemporaryDirectory() as work:
        for comparison in comparisons:
            out = Path(work) / comparison.name
            teleop(*comparison.arguments_with(str(out)), env=env)
            shutil.copyfile(out / "metrics.json", raw / "compare" / f"{comparison.name}.json")
            if comparison.figure:
                shutil.copyfile(out / "constraint_velocity.png", docs / comparison.figure)
            runs["comparisons"][comparison.name] = " ".join(
                ["OPENBLAS_NUM_THREADS=1 teleop", *comparison.arguments_with("DIR")])
            print(f"{comparison.name}: done", file=sys.stderr, flush=True)
            loads.append(round(os.getloadavg()[0], 2))
    runs["machine"]["load_average"] = f"{min(loads):g} to {max(loads):g}"
    (raw / "runs.json").write_text(json.dumps(runs, indent=2) + "\n", encoding="utf-8")
    return runs



# -- rendering: every number from the files -----------------------------------------------

def sci(value: float | None) -> str:
    """``2.7e-07``; ``0`` for an exact zero; ``-`` for a value not computed."""
    if value is None:
        return "-"
    return "0" if value == 0 else f"{value:.1e}"


def fixed(value: float | None, digits: int = 1) -> str:
    """Step times and ratios: 3 significant figures from 100 up, else ``digits`` decimals."""
    if value is None:
        return "-"
    return f"{value:.0f}" if abs(value) >= 100 else f"{value:.{digits}f}"


def markdown_table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    return ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers),
            *("| " + " | ".join(row) + " |" for row in rows)]


def load_raw(raw: Path) -> tuple[dict, list[dict], dict[str, dict]]:
    """``runs.json``, ``bench.json`` and each ``compare/NAME.json`` (in the order of the
    commands in ``runs.json``)."""
    runs = json.loads((raw / "runs.json").read_text(encoding="utf-8"))
    bench = json.loads((raw / "bench.json").read_text(encoding="utf-8"))
    documents = {name: json.loads((raw / "compare" / f"{name}.json").read_text(encoding="utf-8"))
                 for name in runs["comparisons"]}
    return runs, bench, documents


def headline_scenarios(documents: dict[str, dict]) -> list[str]:
    return [name for name in SCENARIOS if name in documents]


def bench_median(bench: Sequence[dict], robot: str, controller: str) -> float | None:
    found = [row["median_us"] for row in bench if row["robot"] == robot
             and row["controller"] == controller]
    return found[0] if found else None


def headline(bench: Sequence[dict], documents: dict[str, dict]) -> list[str]:
    """One table: each controller over the headline scenarios (largest constraint error,
    failed steps, largest joint-limit violation) and its one-step time on the paper's robot
    and on the two-arm one (bench). README.md shows this table as it is here."""
    names = headline_scenarios(documents)
    controllers = list(documents[names[0]]["controllers"]) if names else []
    rows = []
    for spec in controllers:
        metrics = [documents[name]["controllers"][spec] for name in names]
        rows.append([f"`{spec}`", sci(max(m["constraint_error_max_m"] for m in metrics)),
                     str(sum(m["failed_steps"] for m in metrics)),
                     sci(max(m["joint_limit_violation_max_rad"] for m in metrics)),
                     fixed(bench_median(bench, "sda10f", spec)),
                     fixed(bench_median(bench, "sda10f_dual", spec))])
    return markdown_table(["controller", f"constraint error max (m), {len(names)} scenarios",
                           "failed steps", "joint past a limit (rad)",
                           "one step, sda10f (us)", "one step, sda10f_dual (us)"], rows)


def scenario_table(documents: dict[str, dict]) -> list[str]:
    """The largest constraint error per scenario and controller, what no controller may
    do (fail, pass a limit, cross a barrier) over all of them, and each one's largest
    joint-velocity deviation from the reference at the reference's states."""
    names = headline_scenarios(documents)
    if not names:
        return []
    controllers = list(documents[names[0]]["controllers"])
    reference = documents[names[0]]["joint_velocity_reference"]
    others = [spec for spec in controllers if spec != reference]
    rows = []
    for name in names:
        metrics = documents[name]["controllers"]
        rows.append([name, *(sci(metrics[spec]["constraint_error_max_m"]) for spec in controllers),
                     str(sum(m["failed_steps"] for m in metrics.values())),
                     sci(max(m["joint_limit_violation_max_rad"] for m in metrics.values())),
                     sci(max(m["barrier_penetration_max_m"] for m in metrics.values())),
                     " / ".join(sci(metrics[spec]["joint_velocity_deviation_max_radps"])
                                for spec in others)])
    headers = ["scenario", *(f"`{spec}`" for spec in controllers), "failed", "limit (rad)",
               "barrier (m)", f"`|qd - qd_{reference}|` max: " + " / ".join(others)]
    statuses = {}
    for name in names:
        for status, count in documents[name]["controllers"][reference]["status_counts"].items():
            statuses[status] = statuses.get(status, 0) + count
    return [*markdown_table(headers, rows), "",
            f"`{reference}`'s steps by status over the {len(names)} scenarios: "
            + format_status_counts(statuses) + "."]


def comparison_section(name: str, command: str, document: dict) -> list[str]:
    """One comparison in full: each controller's row of the terminal's table, then each
    end effector's and each constraint's errors."""
    imperfect = document["imperfections"]
    lines = [f"### {name}", "", f"`{command}`: {document['description']}; "
             f"{document['duration_s']:g} s at {document['rate_hz']:g} Hz "
             f"({document['steps']} steps), encoder noise {imperfect['encoder_noise_rad']:g} rad, "
             f"latency {imperfect['latency_periods']} periods, joint time constant "
             f"{imperfect['joint_time_constant_s']:g} s.", ""]
    rows = [[f"`{spec}`", *table_cells(m), format_status_counts(m["status_counts"])]
            for spec, m in document["controllers"].items()]
    lines += markdown_table(["controller", *table_headers(document), "steps by status"], rows)
    first = next(iter(document["controllers"].values()))
    frames, parts = list(first["end_effectors"]), list(first["constraints"])
    if len(frames) > 1 or len(parts) > 1:
        rows = [[f"`{spec}`",
                 *(f"{1e3 * m['end_effectors'][f]['position_error_rms_m']:.3f} / "
                   f"{1e3 * m['end_effectors'][f]['position_error_max_m']:.3f}" for f in frames),
                 *(sci(m["constraints"][part]["error_max_m"]) if part in m["constraints"] else "-"
                   for part in parts)]
                for spec, m in document["controllers"].items()]
        headers = ["controller", *(f"{f} position RMS / max (mm)" for f in frames),
                   *(f"{part} max (m)" for part in parts)]
        lines += ["", *markdown_table(headers, rows)]
    if name in NOTES:
        lines += ["", NOTES[name]]
    first_failures = [f"`{spec}`: {m['first_failure']}"
                      for spec, m in document["controllers"].items() if m["first_failure"]]
    if first_failures:
        lines += ["", "First failure: " + "; ".join(first_failures) + "."]
    return lines + [""]


def figure_section(documents: dict[str, dict]) -> list[str]:
    """The paper's Fig 3 with and without encoder noise, their numbers from the runs."""
    if "paper-hole" not in documents or "paper-hole-noise-1e-4" not in documents:
        return []
    clean = documents["paper-hole"]["controllers"]["cjm"]
    noisy = documents["paper-hole-noise-1e-4"]["controllers"]["cjm"]
    return [
        "## The paper's Fig 3, reproduced", "",
        "![lateral velocity at the hole against the EE speed, no noise](fig3_paper_hole.png)", "",
        "The lateral velocity at the hole (`constraint_velocity_rms_mps`) is what the drift "
        f"feedback asks for: {sci(clean['constraint_velocity_rms_mps'])} m/s RMS for `cjm` "
        f"(the hole held to {sci(clean['constraint_error_rms_m'])} m RMS, "
        f"{sci(clean['constraint_error_max_m'])} m max). With 1e-4 rad of encoder noise, as on "
        "the paper's real robot:", "",
        "![the same with 1e-4 rad of encoder noise](fig3_paper_hole_noise_1e-4.png)", "",
        f"the lateral velocity becomes {sci(noisy['constraint_velocity_rms_mps'])} m/s RMS and "
        f"the true hole error {sci(noisy['constraint_error_rms_m'])} m RMS "
        f"({sci(noisy['constraint_error_max_m'])} m max): the drift feedback acting on noisy "
        "measurements (`K` against the encoders at hand, docs/design.md section 3).", ""]


def bench_tables(bench: Sequence[dict]) -> list[str]:
    """The bench's rows, the built-in robots then the generated chains."""
    headers = ["problem", "DoF", "rows", "controller", "median us", "p99 us", "x mink:daqp",
               "x qp:daqp", "max residual (m/s)", "steps by status"]
    builtin = [row for row in bench if not row["robot"].startswith("chain")]
    chains = [row for row in bench if row["robot"].startswith("chain")]
    lines = []
    for title, rows in (("Built-in robots, one hole on each constrained link, near home, a "
                         "teleoperation-sized twist:", builtin),
                        ("Generated chains (`teleop/robots/chains.py`), one hole near the tip "
                         "on 8..64 DoF, then 1..8 holes on 32 DoF:", chains)):
        if rows:
            lines += [title, "", *markdown_table(headers, [
                [row["robot"], str(row["dof"]), str(row["constraint_rows"]),
                 f"`{row['controller']}`",
                 fixed(row["median_us"]), fixed(row["p99_us"]), fixed(row["speedup_vs_mink"]),
                 fixed(row["speedup_vs_qp_daqp"]), sci(row["max_constraint_residual"]),
                 format_status_counts(row["status_counts"])] for row in rows]), ""]
    return lines


def loop_section(documents: dict[str, dict]) -> list[str]:
    """The closed loop's own cost: each headline run's tick beyond its step (``cjm``)."""
    names = [name for name in headline_scenarios(documents)
             if documents[name]["controllers"].get("cjm", {}).get("tick_time_median_us")]
    if not names:
        return []
    rows = [[name, fixed(m["step_time_median_us"]), fixed(m["tick_time_median_us"]),
             fixed(m["tick_time_median_us"] - m["step_time_median_us"])]
            for name in names for m in [documents[name]["controllers"]["cjm"]]]
    return ["## The closed loop's own time (`cjm`, under `teleop compare`)", "",
            "`tick_time_median_us` is the loop's hot path (target filter, EE poses, command, "
            "step, integration); the measures run between ticks, so its caches are cold.", "",
            *markdown_table(["scenario", "step median (us)", "tick median (us)",
                             "beyond the step (us)"], rows), ""]


def render(raw: Path = RAW) -> str:
    """docs/results.md from the raw outputs in ``raw``."""
    runs, bench, documents = load_raw(raw)
    box = runs["machine"]
    versions = ", ".join(f"{name} {version}" for name, version in box["packages"].items())
    lines = [
        "# Measured results", "",
        "<!-- generated by docs/make_results.py from docs/results/: do not edit by hand -->", "",
        "Generated by `python docs/make_results.py render` from the raw outputs kept in "
        "`docs/results/` (`python docs/make_results.py run` measures them again, one command "
        "after the other). Step times are CPU time on a shared machine: compare them within "
        "one run, not across runs.", "",
        f"* **Date:** {runs['date']}.",
        f"* **Machine:** {box['platform']}, {box['processor']}, {box['cpus']} CPUs, "
        f"1-minute load average {box['load_average']} between the runs (other work shared "
        f"the machine), Python {box['python']}.",
        f"* **Packages:** {versions}.",
        "* **Commands** (`DIR`: a temporary folder; its `metrics.json` is kept as "
        "`docs/results/compare/NAME.json`):", "",
        f"  * bench: `{runs['bench']}`",
        *(f"  * {name}: `{command}`" for name, command in runs["comparisons"].items()), "",
        "## Headline", "", *headline(bench, documents), "",
        "## Controller comparison", "",
        "Largest constraint error (m) per scenario and controller, measured at the instant the "
        "robot is at; then, over every controller, failed steps, the largest distance past a "
        "joint limit and behind a barrier; last, each controller's largest joint-velocity "
        "deviation from the reference at the reference's states (rad/s, a shadow evaluation).",
        "", *scenario_table(documents), "",
        "## Each comparison in full", "",
    ]
    for name, command in runs["comparisons"].items():
        lines += comparison_section(name, command, documents[name])
    lines += figure_section(documents)
    lines += ["## One-step time (`teleop bench`)", "",
              "The time is the controller's `solve` call alone (the bench reads `info` and stores "
              "the command after the clock stops); `x mink:daqp`, `x qp:daqp`: how many times "
              "faster than those on the same problem, same run.", "", *bench_tables(bench)]
    lines += loop_section(documents)
    return "\n".join(lines).rstrip() + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("what", choices=("run", "render"),
                        help="run the measurements then render, or render only")
    args = parser.parse_args(argv)
    if args.what == "run":
        run_all()
    RESULTS.write_text(render(RAW), encoding="utf-8")
    print(f"wrote {RESULTS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
