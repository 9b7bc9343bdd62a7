"""``teleop sweep``: its options, and running, showing and reporting cells (docs/sweep.md)."""

from __future__ import annotations

import argparse
import sys

from teleop.limits import MAX_CELLS_UNCONFIRMED

from teleop.experiments.sweep.spec import CELL_FIELDS, CellField
from teleop.options import SWEEP

from .arguments import csv_list, numbers
from .robot_options import add_robot_arguments, robot_options_given, robot_settings
from .termination import CleanedUpInterrupt


def _ints(text: str) -> list[int]:
    try:
        return [int(item) for item in csv_list(text)]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None


def _seeds(text: str) -> int | list[int]:
    """``20`` (a count: seeds 0 to 19) or ``3,7,11`` (those seeds)."""
    values = _ints(text)
    return values[0] if "," not in text else values


def _pair(text: str) -> list[float]:
    values = numbers(text)
    if len(values) != 2:
        raise argparse.ArgumentTypeError(f"expected MM,MRAD, got {text!r}")
    return values


def _numbers(text: str) -> list[int | float]:
    """``"500, 1e3"`` -> ``[500, 1000.0]``: each number as written, an integer or a float
    (argparse type); the spec's validator of the field then checks each (its words)."""
    values: list[int | float] = []
    for item in csv_list(text):
        try:
            values.append(int(item))
        except ValueError:
            try:
                values.append(float(item))
            except ValueError:
                raise argparse.ArgumentTypeError(
                    f"expected comma-separated numbers, got {text!r}") from None
    return values


#: The sweep's own grid options: (option, spec field, parser of its text, metavar, help).
OWN_GRID_OPTIONS = (
    ("--scenarios", "scenarios", csv_list, "NAMES", "comma-separated scenarios (default: the spec's)"),
    ("--controllers", "controllers", csv_list, "SPECS", "comma-separated controllers (default: the spec's)"),
    ("--seeds", "seeds", _seeds, "N|S1,S2", "a count N (seeds 0 to N-1) or a list (default: 1, seed 0)"),
    ("--plants", "plants", csv_list, "KINDS", "kinematic, mujoco (default: kinematic)"),
)


def _declared_fields() -> list[CellField]:
    """The cell fields of the options declared for ``teleop sweep`` (:data:`SWEEP` in
    their ``commands``): each a grid option of its own."""
    return [field for field in CELL_FIELDS
            if field.declared is not None and SWEEP in field.declared.commands]


#: The grid options: the sweep's own, then one per declared field (comma-separated values,
#: each checked by the field's validator: the words of every other front end).
GRID_OPTIONS = OWN_GRID_OPTIONS + tuple(
    (field.declared.option, field.name, _numbers, field.declared.metavar,
     f"{field.declared.help_text()}; comma-separated values (default: "
     f"{field.default_words()})")
    for field in _declared_fields() if field.declared is not None)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("action", nargs="?", choices=("run", "show", "report"), default="run",
                        help="run the sweep; show a cell (its inputs, outcome and the "
                        "compare command that redoes it); make a cell's compare report")
    parser.add_argument("key", nargs="?", help="the cell's key, or its first digits, for show and "
                        "report (default: none)", default="")
    parser.add_argument("--out", required=True, metavar="DIR",
                        help="the sweep's folder: results.sqlite, summary.html, reports/")
    parser.add_argument("--spec", metavar="FILE",
                        help="a TOML or JSON spec (docs/sweep.md); options given replace its "
                        "fields (default: the options alone)")
    grid = parser.add_argument_group("the grid", "each a single value or a comma-separated "
                                     "list: every combination is a cell")
    for option, name, kind, metavar, text in GRID_OPTIONS:
        grid.add_argument(option, dest=name, type=kind, metavar=metavar, help=text)
    add_robot_arguments(parser.add_argument_group(
        "robot", "every cell on this robot (the spec's robot table): paper-hole, "
        "trocar-circle, fast-lateral and joint-limits run on any single arm"),
        "each scenario's own robot")
    grid.add_argument("--calibration-error", dest="calibration_error", type=_pair,
                      metavar="MM,MRAD", help="std of the calibration error of every joint "
                      "placement (default: 0,0)")
    grid.add_argument("--no-acceleration-limits", dest="acceleration_limits",
                      action="store_false", default=None,
                      help="the controllers without the robot's joint acceleration limits "
                      "(default: the spec's, else with them; docs/design.md 8.4)")
    grid.add_argument("--time-limit", dest="time_limit", type=float, metavar="S",
                      help="wall-clock limit of one cell in s (default: 600)")
    engine = parser.add_argument_group("the engine")
    engine.add_argument("--engine", choices=("local", "ray"), default="local",
                        help="local: a pool of worker processes; ray: Ray tasks")
    engine.add_argument("--workers", type=int, help="cells at once (default: the cores)")
    engine.add_argument("--address", help="an existing Ray cluster (default: a local "
                        "instance, started and stopped here)")
    engine.add_argument("--retries", type=int, default=2,
                        help="runs of a cell again after its worker died")
    engine.add_argument("--retry-failed", action="store_true",
                        help="run again the cells the database holds as failed")
    parser.add_argument("--reports", type=int, default=3, metavar="N",
                        help="make the compare reports of the N worst done cells at the end")
    parser.add_argument("--yes", action="store_true",
                        help=f"run a grid of more than {MAX_CELLS_UNCONFIRMED} cells "
                        "(refused without it)")
    parser.add_argument("--quiet", action="store_true", help="no progress")


def options_document(args: argparse.Namespace) -> dict:
    """The grid options given, as spec fields."""
    given = {name: getattr(args, name) for _, name, *_ in GRID_OPTIONS
             if getattr(args, name) is not None}
    for name in (field.name for field in _declared_fields()):
        if name in given and len(given[name]) == 1:
            given[name] = given[name][0]
    if args.calibration_error is not None:
        given["calibration_error_mm"], given["calibration_error_mrad"] = args.calibration_error
    if args.acceleration_limits is not None:
        given["acceleration_limits"] = args.acceleration_limits
    if args.time_limit is not None:
        given["time_limit"] = args.time_limit
    if robot_options_given(args):
        settings = {name: list(value) for name, value in robot_settings(args).items()
                    if value is not None and name not in ("ee_frame", "constrained_link")}
        given["robot"] = {**({"robot": args.robot} if args.robot else {}),
                          **{name: getattr(args, name) for name in ("ee_frame", "constrained_link")
                             if getattr(args, name) is not None}, **settings}
    return given


def run(args: argparse.Namespace) -> int:
    """``teleop sweep``: run, show or report (exit code)."""
    if args.action in ("show", "report"):
        if not args.key:
            raise ValueError(f"{args.action} needs a cell's key")
        return show(args) if args.action == "show" else report(args)
    if args.key:
        raise ValueError(f"unexpected argument {args.key!r} (a key goes after show or report)")
    return run_grid(args)


def run_grid(args: argparse.Namespace) -> int:
    """Run the grid the options ask for, then the summary and the reports (exit code 0).
    Interrupted (Ctrl-C, SIGTERM, SIGHUP): the resume note, then
    :class:`~.termination.CleanedUpInterrupt` once the database is closed and the engine
    stopped."""
    from teleop.experiments.sweep import build_spec, load_spec, run_sweep
    from teleop.experiments.sweep.driver import default_workers, make_engine, sweep_folder
    options = options_document(args)
    spec = load_spec(args.spec, options) if args.spec else build_spec(options)
    if spec.size > MAX_CELLS_UNCONFIRMED and not args.yes:
        raise ValueError(f"the grid has {spec.size} cells, more than {MAX_CELLS_UNCONFIRMED}: "
                         "give --yes to run them all")
    workers = default_workers() if args.workers is None else args.workers
    make_engine(args.engine, workers, args.retries, args.address)  # refused before any work
    if args.reports < 0:
        raise ValueError(f"--reports must be >= 0, got {args.reports}")
    folder = sweep_folder(args.out)
    for note in spec.notes:
        print(f"note: {note}", file=sys.stderr)
    print(f"sweep: {spec.size} cells ({spec.source}) into {folder}, engine {args.engine}, "
          f"{workers} workers", file=sys.stderr)
    try:
        outcome = run_sweep(spec, folder, args.engine, workers, args.retries, args.address,
                            args.retry_failed, progress=not args.quiet)
    except KeyboardInterrupt as interrupt:
        print("sweep: interrupted; every finished cell is written, the same command resumes",
              file=sys.stderr)
        # the database is closed, the workers and a local Ray instance stopped: the
        # program may end without the interpreter's teardown (docs/sweep.md)
        raise CleanedUpInterrupt(*interrupt.args) from None
    print(outcome.throughput_line(workers))
    if outcome.skipped:
        print(f"skipped {outcome.skipped} cells the database held")
    if outcome.written_elsewhere:
        print(f"{outcome.written_elsewhere} cells were written by another sweep first")
    from teleop.experiments.sweep.summary import finish_sweep

    print(finish_sweep(spec, folder, args.reports))
    return 0


def show(args: argparse.Namespace) -> int:
    from teleop.experiments.sweep.summary import describe_row
    from teleop.experiments.sweep.database import DATABASE_NAME, ResultsDatabase

    with ResultsDatabase(_existing(args.out) / DATABASE_NAME) as database:
        print(describe_row(database.row(args.key)))
    return 0


def report(args: argparse.Namespace) -> int:
    from teleop.experiments.sweep.database import DATABASE_NAME, ResultsDatabase
    from teleop.experiments.sweep.summary import make_report

    folder = _existing(args.out)
    with ResultsDatabase(folder / DATABASE_NAME) as database:
        row = database.row(args.key)
    print(f"wrote {make_report(row, folder)}")
    return 0


def _existing(out: str):
    from pathlib import Path

    from teleop.experiments.sweep.database import DATABASE_NAME

    folder = Path(out)
    if not (folder / DATABASE_NAME).is_file():
        raise ValueError(f"{folder} holds no sweep ({DATABASE_NAME} missing)")
    return folder
