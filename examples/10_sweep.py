"""A small Monte-Carlo sweep: the CJM and the QP (daqp) on `paper-hole` with encoder noise,
each trocar slid along its link and the operator's path varied at random, 4 seeds; the
cells run on a local process pool, each written to a results database as it finishes, and
an HTML summary (docs/sweep.md). Run it twice: the second run finds every cell done."""

import sys
from pathlib import Path

from teleop.experiments.sweep import build_spec, run_sweep
from teleop.experiments.sweep.summary import finish_sweep

if __name__ == "__main__":  # the pool's workers are spawned: they import this module
    spec = build_spec({
        "scenarios": ["paper-hole"],
        "controllers": ["cjm", "qp:daqp"],
        "seeds": 4,
        "duration": 1.0,
        "imperfections": {"encoder_noise": 1e-4},
        "variations": {"trocar_shift": 0.01, "path_amplitude": 0.005},
    })
    out = sys.argv[1] if len(sys.argv) > 1 else "sweep_out"
    run = run_sweep(spec, out, workers=2, progress=False)
    print(f"cells done = {run.done}, failed = {run.failed}, skipped = {run.skipped}")
    print(run.throughput_line(workers=2))
    print(finish_sweep(spec, Path(out), reports=1))
