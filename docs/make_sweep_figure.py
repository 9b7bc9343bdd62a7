"""The README's sweep figure: one metric's box plot per controller from a sweep's results
database, as the summary draws it.

``python docs/make_sweep_figure.py SWEEP_FOLDER [--metric port_force_max_n] [--out PATH]``
(the README's: ``teleop sweep --spec docs/sweeps/port_force.toml --out sweep_port_force``,
then this on ``sweep_port_force``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from teleop.experiments.sweep.database import DATABASE_NAME, ResultsDatabase
from teleop.experiments.sweep.summary import SUMMARY_METRICS, metric_values
from teleop.experiments.sweep.summary_plots import box_plot

OUT = Path(__file__).resolve().parent / "images" / "sweep_port_force.png"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="the sweep's folder")
    parser.add_argument("--metric", default="port_force_max_n",
                        choices=[metric.key for metric in SUMMARY_METRICS])
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    (metric,) = [m for m in SUMMARY_METRICS if m.key == args.metric]
    with ResultsDatabase(args.folder / DATABASE_NAME) as database:
        rows = database.rows()
    scenarios = sorted({row.inputs["scenario"] for row in rows})
    title = f"{metric.label} over {len(rows)} cells ({', '.join(scenarios)})"
    args.out.write_bytes(box_plot(metric_values(rows, metric), title, metric.heading,
                                  integer=metric.summed))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
