"""Command line: ``teleop compare | replay | record | scenarios | bench`` and the commands
registered from the layers above (``teleop web``, :mod:`teleop.cli.commands`); docs/cli.md.
"""

from __future__ import annotations

import argparse
import sys
from importlib import metadata
from typing import Callable, Sequence

from teleop.controller_specs import CONTROLLER_HELP, CONTROLLER_SPECS, default_specs
from teleop.limits import (
    MAX_BENCH_ITERATIONS,
    MAX_DURATION_S,
    MAX_ENCODER_NOISE_RAD,
    MAX_LATENCY_PERIODS,
    MAX_LATENCY_S,
    MAX_RATE_HZ,
    MAX_TIME_CONSTANT_S,
)
from teleop.robots import BUILTIN_ROBOTS

from .arguments import ArgumentParser, HelpFormatter, bounded, csv_list, one_line, sentence
from .commands import Command, registered_commands

PACKAGE = "cjm-teleop"
DEFAULT_CONTROLLERS = ", ".join(default_specs("compare"))
DEFAULT_BENCH_CONTROLLERS = ", ".join(default_specs("bench"))
DEFAULT_BENCH_ROBOTS = ", ".join(BUILTIN_ROBOTS)


def package_version() -> str:
    """The installed version of the package (``importlib.metadata``)."""
    try:
        return metadata.version(PACKAGE)
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


#: The option types, bounded by the maxima of :mod:`teleop.limits`.
rate = bounded(float, 0.0, MAX_RATE_HZ, inclusive_minimum=False, unit="Hz")
duration = bounded(float, 0.0, MAX_DURATION_S, inclusive_minimum=False, unit="s")
encoder_noise = bounded(float, 0.0, MAX_ENCODER_NOISE_RAD, unit="rad")
time_constant = bounded(float, 0.0, MAX_TIME_CONSTANT_S, unit="s")
latency = bounded(int, 0, MAX_LATENCY_PERIODS)
count = bounded(int, 0)
iterations = bounded(int, 1, MAX_BENCH_ITERATIONS)


def _controllers_epilog(context: str) -> str:
    """The known controllers, one a line; ``*`` marks those run by default."""
    width = max(len(spec.name) for spec in CONTROLLER_SPECS)
    lines = ["controllers (* = in the default list):"]
    lines += [f"  {'*' if context in spec.offered_in else ' '} {spec.name:<{width}}  {spec.description}"
              for spec in CONTROLLER_SPECS]
    lines += ["in general: " + CONTROLLER_HELP.replace(" with ", "\n  with ")]
    return "\n".join(lines)


def _add_command(commands, name: str, summary: str, run: Callable[[argparse.Namespace], int],
                 **kwargs) -> argparse.ArgumentParser:
    """A subcommand whose one-line summary is both its help (in ``teleop -h``) and
    description, run by ``run(args)``."""
    parser = commands.add_parser(name, help=summary, description=sentence(summary),
                                 formatter_class=HelpFormatter, strict=True, **kwargs)
    parser.set_defaults(run_command=run)
    return parser


def _add_registered(commands) -> None:
    """The commands of the entry-point group (:mod:`teleop.cli.commands`), after the
    built-in ones; one that cannot be loaded says why when it is run."""
    for entry in registered_commands(taken=set(commands.choices)):
        if entry.command is None:
            commands.add_parser(entry.name, help=entry.unavailable, unavailable=entry.unavailable)
            continue
        parser = _add_command(commands, entry.name, entry.command.summary,
                              _registered_run(entry.command, f"teleop {entry.name}"),
                              epilog=entry.command.epilog or None)
        entry.command.add_arguments(parser)


def _registered_run(command: Command, prog: str) -> Callable[[argparse.Namespace], int]:
    return lambda args: command.run(args, prog)


def _add_run_options(parser: argparse.ArgumentParser, source: str) -> None:
    parser.add_argument("--controllers", type=csv_list, default=DEFAULT_CONTROLLERS,
                        help="comma-separated controllers, see the list below")
    if source == "session":
        parser.add_argument("--rate", type=rate, help="control rate in Hz, at most "
                            f"{MAX_RATE_HZ:g} (default: the session's rate, else 1000)")
    else:
        parser.add_argument("--rate", type=rate, default=1000.0,
                            help=f"control rate in Hz, at most {MAX_RATE_HZ:g}")
    parser.add_argument("--duration", type=duration,
                        help=f"seconds to run, at most {MAX_DURATION_S:g} (default: the whole "
                        f"{source})")
    parser.add_argument("--out", default="out", help="output directory")
    parser.add_argument("--no-plots", action="store_true",
                        help="write the metrics only, no plots and no report.html")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    robot = parser.add_argument_group(
        "a robot that is not perfect", "the same for every controller; off by default "
        "(docs/design.md section 15.1)")
    robot.add_argument("--encoder-noise", type=encoder_noise, default=0.0, metavar="RAD",
                       help="std of the Gaussian noise on each measured joint, every period, "
                       f"at most {MAX_ENCODER_NOISE_RAD:g}")
    robot.add_argument("--latency", type=latency, default=0, metavar="PERIODS",
                       help="control periods between a command and the joints, at most "
                       f"{MAX_LATENCY_S:g} s")
    robot.add_argument("--joint-time-constant", type=time_constant, default=0.0, metavar="S",
                       help="first-order response of the joint velocities to their command, "
                       f"at most {MAX_TIME_CONSTANT_S:g}")
    robot.add_argument("--seed", type=count, default=0, help="seed of the encoder noise")


def build_parser(registered: bool = True) -> argparse.ArgumentParser:
    """``teleop``'s parser: the built-in commands and, with ``registered``, those of the
    entry-point group (loading them imports their layers: ``web`` imports viser)."""
    parser = ArgumentParser(
        prog="teleop", formatter_class=HelpFormatter,
        description="Operational-space teleoperation under kinematic constraints (CJM, QP, mink).")
    parser.add_argument("--version", action="version", version=package_version(),
                        help="print the installed version and exit")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                     parser_class=ArgumentParser)

    compare = _add_command(commands, "compare", "run controllers on a scripted scenario and "
                           "write metrics and plots", _compare,
                           epilog=_controllers_epilog("compare"))
    compare.add_argument("--scenario", required=True, help="scenario name (see 'teleop scenarios')")
    _add_run_options(compare, "scenario")

    replay = _add_command(commands, "replay", "replay a recorded session through controllers "
                          "and write metrics and plots", _replay,
                          epilog=_controllers_epilog("compare"))
    replay.add_argument("file", help="session file (JSON lines, see docs/sessions.md)")
    _add_run_options(replay, "session")

    record = _add_command(commands, "record", "write a scenario's operator input as a session "
                          "file", _record)
    record.add_argument("--scenario", required=True, help="scenario name (see 'teleop scenarios')")
    record.add_argument("--rate", type=rate, default=1000.0,
                        help=f"control rate in Hz, at most {MAX_RATE_HZ:g} (one recorded "
                        "target per tick)")
    record.add_argument("--duration", type=duration,
                        help=f"seconds to record, at most {MAX_DURATION_S:g} (default: the whole "
                        "scenario)")
    record.add_argument("file", help="session file to write")

    _add_command(commands, "scenarios", "list the scripted scenarios", _scenarios)

    bench = _add_command(commands, "bench", "time one control step of each controller on each "
                         "robot", _bench, epilog=_controllers_epilog("bench"))
    bench.add_argument("--robots", type=csv_list, default=DEFAULT_BENCH_ROBOTS,
                       help="comma-separated built-in robots")
    bench.add_argument("--controllers", type=csv_list, default=DEFAULT_BENCH_CONTROLLERS,
                       help="comma-separated controllers, see the list below")
    bench.add_argument("--iterations", type=iterations, default=2000,
                       help=f"timed steps per controller, at most {MAX_BENCH_ITERATIONS}")
    bench.add_argument("--quick", action="store_true",
                       help="20 iterations and small scaling runs (CI smoke run)")
    bench.add_argument("--no-scaling", action="store_true",
                       help="skip the generated-chain scaling runs")
    bench.add_argument("--json", metavar="FILE",
                       help="also write the results as JSON to FILE (default: no JSON)")

    if registered:
        _add_registered(commands)
    return parser


#: The subcommands defined here: running one loads no registered command.
BUILT_IN = ("compare", "replay", "record", "scenarios", "bench")


def main(argv: Sequence[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(registered=not argv or argv[0] not in BUILT_IN).parse_args(argv)
    try:
        return args.run_command(args)
    except ValueError as error:  # bad scenario, controller, file: one clear line
        print(f"teleop {args.command}: {one_line(error)}", file=sys.stderr)
        return 2


def _run(plan, args: argparse.Namespace, config) -> int:
    """Compare the controllers on ``plan``, write the outputs, print the table."""
    from teleop.experiments.compare import (
        compare,
        metrics_document,
        output_directory,
        write_outputs,
    )
    from teleop.plants.imperfect import Imperfections
    from teleop.experiments.metrics_table import format_table

    output_directory(args.out)  # before minutes of simulation
    imperfections = Imperfections(args.encoder_noise, args.latency, args.joint_time_constant,
                                  args.seed)
    duration = args.duration or plan.duration
    results = compare(plan, args.controllers, config, duration, progress=not args.quiet,
                      imperfections=imperfections)
    paths = write_outputs(plan, results, config, duration, args.out, plots=not args.no_plots,
                          imperfections=imperfections)
    document = metrics_document(plan, results, config, duration, imperfections)
    print(f"{plan.name}: {plan.description} ({duration:g} s at {config.rate:g} Hz, "
          f"{imperfections.describe()})")
    print(format_table(document))
    for spec, result in results.items():
        if result.failure_messages:
            print(f"  {spec}: {len(result.failure_messages)}+ failed steps, first {result.failure_messages[0]}")
        if result.solver_messages:
            print(f"  {spec}: the solver wrote {sum(result.solver_messages.values())} lines "
                  f"({len(result.solver_messages)} distinct), kept in metrics.json")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def _compare(args: argparse.Namespace) -> int:
    from teleop.experiments.scenarios import load_scenario
    from teleop.loop import LoopConfig

    return _run(load_scenario(args.scenario), args, LoopConfig(rate=args.rate or 1000.0))


def _replay(args: argparse.Namespace) -> int:
    from teleop.experiments.sessions import load_session, session_plan
    from teleop.loop import LoopConfig

    session = load_session(args.file)
    header = session.header
    config = LoopConfig(rate=args.rate or header.get("rate_hz", 1000.0),
                        kp=header.get("kp", 20.0),
                        target_time_constant=header.get("target_time_constant_s", 0.0))
    return _run(session_plan(session), args, config)


def _record(args: argparse.Namespace) -> int:
    from teleop.experiments.scenarios import load_scenario
    from teleop.experiments.sessions import record_plan

    path = record_plan(load_scenario(args.scenario), args.file, args.rate, args.duration)
    print(f"wrote {path}")
    return 0


def _scenarios(args: argparse.Namespace) -> int:
    from teleop.experiments.scenarios import SCENARIOS, load_scenario

    for name in SCENARIOS:
        print(f"{name:<15} {load_scenario(name).description}")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from teleop.experiments.bench import format_table, run_bench, run_scaling, write_json

    iterations = 20 if args.quick else args.iterations
    results = run_bench(args.robots, args.controllers, iterations=iterations)
    if not args.no_scaling:
        results += run_scaling(iterations=max(5, iterations // 5),
                               dofs=(8, 16) if args.quick else (8, 16, 32, 64),
                               holes=(1, 2) if args.quick else (1, 2, 4, 8))
    print(format_table(results))
    for r in results:
        if r.solver_messages:
            print(f"  {r.robot} {r.controller}: the solver wrote "
                  f"{sum(r.solver_messages.values())} lines, kept in solver_messages"
                  + (" of the JSON" if args.json else " (--json FILE writes them)"))
    if args.json:
        write_json(results, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
