"""``teleop sweep``: Monte-Carlo comparisons, a grid of ``compare`` cells run on a local
process pool or Ray, each written to a results database as it finishes; resumable; an
HTML summary (docs/sweep.md)."""

from .cell import compare_command, run_cell
from .database import ResultsDatabase
from .driver import run_sweep
from .spec import Cell, SweepSpec, build_spec, load_spec

__all__ = ["Cell", "ResultsDatabase", "SweepSpec", "build_spec", "compare_command",
           "load_spec", "run_cell", "run_sweep"]
