"""The README's palpation figure and design.md 21.4's table: the contact force while the
tip slides on the tissue, for each controller (:mod:`teleop.experiments.palpation`).

``python docs/make_palpation_figure.py [--out PATH] [--controllers cjm qp:daqp mink:daqp]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from teleop.experiments.palpation import (  # noqa: E402
    SETPOINT, SETTLE, SLIDE_TIME, run_palpation, slide)

OUT = Path(__file__).resolve().parent / "images" / "palpation_force.png"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--controllers", nargs="+", default=["cjm", "qp:daqp", "mink:daqp"])
    args = parser.parse_args()
    figure, (force_axis, slide_axis) = plt.subplots(
        2, 1, figsize=(8, 5), sharex=True, gridspec_kw={"height_ratios": [3, 1]})
    print("| controller | force error RMS / max (N) | contact lost (periods) | port force max (N) "
          "| hole error max (mm) | EE error max (mm) | jerk max (rad/s^3) |")
    print("|---|---|---|---|---|---|---|")
    for spec, style in zip(args.controllers, ["-", "--", ":"]):
        measures = run_palpation(spec)
        force_axis.plot(measures.times, measures.forces, style, label=spec)
        print(f"| {spec} | {measures.force_error_rms:.4f} / {measures.force_error_max:.4f} | "
              f"{measures.contact_lost} | {measures.port_force_max:.3f} | "
              f"{measures.hole_error_max * 1e3:.3f} | {measures.ee_error_max * 1e3:.2f} | "
              f"{measures.jerk_max:.3g} |")
    times = measures.times
    force_axis.axhline(SETPOINT, color="grey", linewidth=0.8, label="setpoint")
    for axis in (force_axis, slide_axis):
        axis.axvspan(SETTLE, SETTLE + SLIDE_TIME, color="0.93")
    force_axis.set_ylabel("contact force (N)")
    force_axis.set_title("palpation through the trocar: 1 N along the tool, 2 cm slide and back")
    force_axis.legend(loc="lower right")
    slide_axis.plot(times, [slide(t) * 1e3 for t in times], color="black")
    slide_axis.set_ylabel("target slide (mm)")
    slide_axis.set_xlabel("time (s)")
    figure.tight_layout()
    figure.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
