"""Closed loop: the CJM and a QP follow the same operator motion on the paper's robot.

The ``paper-hole`` scenario is the sda10f with a trocar on link 6 and a smooth,
operator-like target (+-1.5 cm, +-0.03 rad). Each controller runs the same 1 kHz loop
(target -> EE twist -> controller -> integrate); ``compare`` measures every tick and
``write_outputs`` writes metrics.json, metrics.csv and the plots (the paper's Figs 3-4).

Run:  python examples/02_closed_loop.py [OUT_DIR] [--seconds S]   (default: a temp dir, 3 s)
"""

import argparse
import json
import tempfile
from pathlib import Path

from teleop.experiments.compare import compare, write_outputs
from teleop.experiments.scenarios import load_scenario
from teleop.loop import LoopConfig

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("out", nargs="?", help="output directory (default: a new temp dir)")
parser.add_argument("--seconds", type=float, default=3.0, help="simulated seconds")
args = parser.parse_args()
out = Path(args.out or tempfile.mkdtemp(prefix="cjm-closed-loop-"))

plan = load_scenario("paper-hole")
config = LoopConfig(rate=1000.0)
specs = ["cjm", "qp:daqp"]
print(f"{plan.name}: {plan.description}")
print(f"running {', '.join(specs)} for {args.seconds:g} s at {config.rate:g} Hz ...")

results = compare(plan, specs, config, duration=args.seconds, progress=False)
paths = write_outputs(plan, results, config, args.seconds, out)

metrics = json.loads((out / "metrics.json").read_text())["controllers"]
print()
print(f"{'controller':<10} {'constr err max (m)':>18} {'residual (m/s)':>15} "
      f"{'EE pos RMS (mm)':>15} {'failed':>6} {'step median (us)':>16}")
for spec, m in metrics.items():
    print(f"{spec:<10} {m['constraint_error_max_m']:>18.2e} "
          f"{m['constraint_velocity_residual_max_mps']:>15.1e} "
          f"{1e3 * m['ee_position_error_rms_m']:>15.4f} {m['failed_steps']:>6d} "
          f"{m['step_time_median_us']:>16.0f}")

# the two controllers compute the same joint velocities, so they follow the same path
difference = abs(metrics["cjm"]["ee_position_error_rms_m"]
                 - metrics["qp:daqp"]["ee_position_error_rms_m"])
print(f"\n|EE RMS error cjm - qp:daqp| = {difference:.2e} m")
print("wrote " + ", ".join(p.name for p in paths) + f" to {out}")
