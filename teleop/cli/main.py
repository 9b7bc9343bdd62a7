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
    MAX_CALIBRATION_POSITION_STD_M,
    MAX_CALIBRATION_ROTATION_STD_RAD,
)
from teleop.experiments.bench_problems import DEFAULT_PROBLEMS
from teleop.options import (ACCELERATION_LIMITS_HELP, BENCH, CALIBRATION_POSITION, COMPARE,
                            RECORD, REPLAY,
                            CALIBRATION_ROTATION, CONSTRAINT_GAIN, DURATION, ENCODER_NOISE,
                            JERK_LIMIT, JOINT_TIME_CONSTANT, KP, LATENCY, PATH_AMPLITUDE, RATE,
                            SEED, TROCAR_SHIFT)

from .arguments import (ArgumentParser, HelpFormatter, add_damper_options, bounded, csv_list,
                        damper_settings, one_line, sentence)
from .commands import Command, registered_commands
from .contact_options import add_contact_options, run_contact_compare
from .robot_options import add_robot_arguments, robot_from_arguments, robot_options_given
from .plant_options import add_plant_group, plant_choice
from .sim import add_arguments as add_sim_arguments
from .sim import run as run_sim
from .state_observer_options import add_state_observer_option
from .supervisor_options import add_supervisor_options, supervisor_choice
from .sweep import add_arguments as add_sweep_arguments
from .sweep import run as run_sweep_command
from .termination import CleanedUpInterrupt, end_process, terminations_interrupt

PACKAGE = "cjm-teleop"
DEFAULT_CONTROLLERS = ", ".join(default_specs("compare"))
DEFAULT_BENCH_CONTROLLERS = ", ".join(default_specs("bench"))
DEFAULT_BENCH_PROBLEMS = ", ".join(DEFAULT_PROBLEMS)


def package_version() -> str:
    """The installed version of the package (``importlib.metadata``)."""
    try:
        return metadata.version(PACKAGE)
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


#: The bench's own option type (the shared ones: :mod:`teleop.options`).
iterations = bounded(int, 1, MAX_BENCH_ITERATIONS)


def calibration_error(text: str) -> tuple[float, float]:
    """``"MM,MRAD"`` -> the calibration error's stds ``(m, rad)`` (argparse type), each
    bounded by :mod:`teleop.limits`."""
    parts = text.split(",")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"expected MM,MRAD (two numbers), got {text!r}")
    position, rotation = parts
    try:
        millimetres = CALIBRATION_POSITION.parse(position.strip())
    except argparse.ArgumentTypeError as error:
        raise argparse.ArgumentTypeError(f"the position std {error}") from None
    try:
        milliradians = CALIBRATION_ROTATION.parse(rotation.strip())
    except argparse.ArgumentTypeError as error:
        raise argparse.ArgumentTypeError(f"the rotation std {error}") from None
    return millimetres * 1e-3, milliradians * 1e-3

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
        RATE.add_to(parser, left_out="the session's rate, else 1000")
    else:
        RATE.add_to(parser, 1000.0)
    DURATION.add_to(parser, left_out=f"the whole {source}")
    parser.add_argument("--out", default="out", help="output directory")
    parser.add_argument("--no-plots", action="store_true",
                        help="write the metrics only, no plots and no report.html")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--acceleration-limits", action=argparse.BooleanOptionalAction,
                        default=True, help=ACCELERATION_LIMITS_HELP)
    JERK_LIMIT.add_to(parser, left_out="none")
    robot = parser.add_argument_group(
        "a robot that is not perfect", "the same for every controller; off by default "
        "(docs/design.md section 15.1)")
    ENCODER_NOISE.add_to(robot, 0.0)
    LATENCY.add_to(robot, 0)
    JOINT_TIME_CONSTANT.add_to(robot, 0.0)
    robot.add_argument("--calibration-error", type=calibration_error, metavar="MM,MRAD",
                       help="std of the translation (mm) and rotation (mrad) error, per axis, "
                       "of every joint placement of the true robot; the controllers keep the "
                       "model, the errors are measured on the true robot, at most "
                       f"{MAX_CALIBRATION_POSITION_STD_M * 1e3:g},"
                       f"{MAX_CALIBRATION_ROTATION_STD_RAD * 1e3:g}; the kinematic plant only "
                       "(default: 0,0)")
    SEED.add_to(robot, 0)
    _add_variation_options(parser, source)
    add_plant_group(parser, REPLAY if source == "session" else COMPARE,
                    "the session's plant (its header), else the defaults"
                    if source == "session" else "its default")
    _add_collision_options(parser, source)
    add_supervisor_options(parser)
    add_state_observer_option(parser)


def _add_variation_options(parser: argparse.ArgumentParser, source: str) -> None:
    """The random variations and the gains (docs/cli.md; docs/design.md section 15.1.1)."""
    group = parser.add_argument_group(
        "random variations", f"the {source}'s trocars and operator paths drawn from --seed, "
        "the same for every controller; off by default (docs/design.md section 15.1.1)")
    TROCAR_SHIFT.add_to(group, 0.0)
    PATH_AMPLITUDE.add_to(group, 0.0)
    gains = parser.add_argument_group("gains", "the loop's and the constraints' feedback gains")
    KP.add_to(gains, left_out="the session's, else 20" if source == "session" else "20")
    CONSTRAINT_GAIN.add_to(gains, left_out="each constraint's own")


def _add_collision_options(parser: argparse.ArgumentParser, source: str) -> None:
    """``--collisions`` / ``--no-collisions`` and the damper's numbers (docs/cli.md)."""
    group = parser.add_argument_group(
        "collision avoidance", f"every controller keeps the robot's links apart and off the "
        f"obstacles the {source} declares (docs/design.md section 18); an option left out: "
        f"the {source}'s setting, else the default")
    switch = group.add_mutually_exclusive_group()
    switch.add_argument("--collisions", dest="collisions", action="store_true", default=None,
                        help=f"on, also for a {source} that declares none (self-collision, "
                        f"no obstacle) (default: what the {source} declares)")
    switch.add_argument("--no-collisions", dest="collisions", action="store_false",
                        default=None, help=f"off, also for a {source} that declares it "
                        f"(default: what the {source} declares)")
    add_damper_options(group)


def collision_choice(args: argparse.Namespace, plan):
    """``plan`` with the collision avoidance the options ask for over what it declares
    (``plan.collisions``): ``--no-collisions`` drops it, ``--collisions`` adds the default
    one (self-collision, no obstacle) when it declares none, each damper option given
    replaces its value. ``ValueError`` (one line) for a damper option without collision
    avoidance or settings it refuses (``d_i <= d_s``)."""
    from dataclasses import replace

    from constraints.collision import CollisionAvoidance

    enabled = plan.collisions is not None if args.collisions is None else args.collisions
    given = damper_settings(args)
    if not enabled:
        if given:
            raise ValueError(f"{', '.join(option for option, _ in given.values())} "
                             f"need{'s' * (len(given) == 1)} collision avoidance "
                             f"(--collisions; {plan.name} declares "
                             f"{'it' if plan.collisions is not None else 'none'})")
        return replace(plan, collisions=None)
    settings = dict(plan.collisions if plan.collisions is not None
                    else CollisionAvoidance(plan.robot).to_dict())
    settings.update({name: value for name, (_, value) in given.items()})
    try:
        CollisionAvoidance.from_dict(plan.robot, settings)
    except ValueError as error:
        raise ValueError(f"collision avoidance: {error}") from None
    return replace(plan, collisions=settings)


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
    _add_scenario_robot(compare)
    _add_run_options(compare, "scenario")
    add_contact_options(compare)

    replay = _add_command(commands, "replay", "replay a recorded session through controllers "
                          "and write metrics and plots", _replay,
                          epilog=_controllers_epilog("compare"))
    replay.add_argument("file", help="session file (JSON lines, see docs/sessions.md)")
    _add_run_options(replay, "session")

    record = _add_command(commands, "record", "write a scenario's operator input as a session "
                          "file", _record)
    record.add_argument("--scenario", required=True, help="scenario name (see 'teleop scenarios')")
    _add_scenario_robot(record)
    RATE.add_to(record, 1000.0)
    DURATION.add_to(record, left_out="the whole scenario")
    record.add_argument("file", help="session file to write")
    add_plant_group(record, RECORD, "its default; the plant is written in the session's "
                    "header for 'teleop replay'")
    _add_collision_options(record, "scenario")

    _add_command(commands, "scenarios", "list the scripted scenarios", _scenarios)
    _add_command(commands, "robots", "list the built-in robots and the example-robot-data "
                 "URDFs installed (each a --robot)", _robots)

    bench = _add_command(commands, "bench", "time one control step of each controller on each "
                         "robot", _bench, epilog=_controllers_epilog("bench"))
    bench.add_argument("--robots", type=csv_list, default=DEFAULT_BENCH_PROBLEMS,
                       help="comma-separated built-in robots (one hole on each constrained "
                            "link) and problems: sda10f/plane, sda10f/lock, sda10f/barrier "
                            "(one constraint of that type), chain8..chain64 (one hole), "
                            "chain32/2holes..chain32/8holes")
    bench.add_argument("--controllers", type=csv_list, default=DEFAULT_BENCH_CONTROLLERS,
                       help="comma-separated controllers, see the list below")
    bench.add_argument("--iterations", type=iterations, default=2000,
                       help=f"timed steps per controller, at most {MAX_BENCH_ITERATIONS}")
    bench.add_argument("--quick", action="store_true",
                       help="20 iterations and small scaling runs (CI smoke run)")
    bench.add_argument("--no-scaling", action="store_true",
                       help="skip the generated-chain scaling runs")
    bench.add_argument("--no-allocations", action="store_true",
                       help="skip counting the heap allocations per step (a subprocess per "
                            "problem; without a C compiler they read n/a)")
    bench.add_argument("--no-loop", action="store_true",
                       help="skip timing the closed loop's hot path on paper-hole (10 s at "
                            "1 kHz, the compiled tick and the Python path; 1 s with --quick)")
    bench.add_argument("--json", metavar="FILE",
                       help="also write the results, their ratios and the targets as JSON to "
                            "FILE (default: no JSON)")
    add_plant_group(bench, BENCH, "its default; with --plant, each control period's tick is "
                    "timed on the kinematic plant and on this one (the built-in robots)")

    sim = _add_command(commands, "sim", "serve a simulated robot on ROS 2 as ros2_control "
                       "or CRTK would (docs/ros2.md)", run_sim)
    add_sim_arguments(sim)

    sweep = _add_command(commands, "sweep", "run compare cells over a grid of scenarios, "
                         "controllers, seeds and imperfections on a process pool or Ray, "
                         "resumable, with a results database and a summary", _sweep,
                         epilog="docs/sweep.md has the spec's fields and the database")
    add_sweep_arguments(sweep)

    if registered:
        _add_registered(commands)
    return parser


#: The subcommands defined here: running one loads no registered command.
BUILT_IN = ("compare", "replay", "record", "scenarios", "robots", "bench", "sim", "sweep")


def main(argv: Sequence[str] | None = None) -> int:
    """The ``teleop`` program: its exit code. Without ``argv`` it is the program itself
    (the ``teleop`` script, ``python -m teleop``: ``sys.argv``), and a command stopped
    after its cleanup ran to the end (:class:`~.termination.CleanedUpInterrupt`) ends the
    process there; with ``argv`` (a test, a script) every command returns its code."""
    program = argv is None
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser(registered=not argv or argv[0] not in BUILT_IN).parse_args(argv)
    try:
        with terminations_interrupt():  # SIGTERM unwinds as Ctrl-C: a robot gets its zeros
            return args.run_command(args)
    except ValueError as error:  # bad scenario, controller, file: one clear line
        print(f"teleop {args.command}: {one_line(error)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:  # Ctrl-C, SIGTERM or SIGHUP: stopped, cleaned up
        print(f"teleop {args.command}: stopped ({str(interrupt) or 'SIGINT'})", file=sys.stderr)
        if program and isinstance(interrupt, CleanedUpInterrupt):
            end_process(130)  # nothing left open: the interpreter's teardown skipped
        return 130


def _run(plan, args: argparse.Namespace, config, plant) -> int:
    """Compare the controllers on ``plan`` on ``plant``, write the outputs, print the
    tables."""
    from teleop.experiments.compare import (
        compare,
        metrics_document,
        output_directory,
        write_outputs,
    )
    from teleop.plants.imperfect import Imperfections
    from teleop.experiments.metrics_table import (format_body_table, format_collision_table,
                                                  format_table)

    from teleop.experiments.variations import Variation
    from teleop.loop import LoopConfig

    output_directory(args.out)  # before minutes of simulation
    position_std, rotation_std = args.calibration_error or (0.0, 0.0)
    imperfections = Imperfections(args.encoder_noise, args.latency, args.joint_time_constant,
                                  args.seed, calibration_position_std=position_std,
                                  calibration_rotation_std=rotation_std)
    variation = Variation(args.trocar_shift, args.path_amplitude, args.seed)
    plan = variation.apply(plan)
    if args.constraint_gain is not None:
        plan = plan.with_constraint_gain(args.constraint_gain)
    duration = args.duration or plan.duration
    results = compare(plan, args.controllers, config, duration, progress=not args.quiet,
                      imperfections=imperfections, plant=plant,
                      acceleration_limits=args.acceleration_limits, jerk_limit=args.jerk_limit)
    paths = write_outputs(plan, results, config, duration, args.out, plots=not args.no_plots,
                          imperfections=imperfections, plant=plant,
                          acceleration_limits=args.acceleration_limits, variation=variation,
                          jerk_limit=args.jerk_limit)
    document = metrics_document(plan, results, config, duration, imperfections, plant,
                                args.acceleration_limits, variation, args.jerk_limit)
    limits = "; acceleration limits" if args.acceleration_limits else ""
    if args.jerk_limit is not None:
        limits += f", jerk limit {args.jerk_limit:g} rad/s^3"
    if plan.collisions is not None:
        limits += (f"; collision avoidance d_s = {1e3 * plan.collisions['safety_distance']:g} "
                   f"mm, {len(plan.collisions['obstacles'])} obstacles")
    if config.kp != LoopConfig.kp:
        limits += f"; K_p {config.kp:g} 1/s"
    if variation.active:
        limits += f"; {variation.describe()}"
    if plan.constraint_gain is not None:
        limits += f"; constraint gain {plan.constraint_gain:g} 1/s"
    print(f"{plan.name}: {plan.description} ({duration:g} s at {config.rate:g} Hz, "
          f"{imperfections.describe()}; {plant.describe()}{limits}; "
          f"{config.supervisor.describe()})")
    print(format_table(document))
    print()
    print(format_body_table(document))
    if plan.collisions is not None:
        print()
        print(format_collision_table(document))
    for spec, result in results.items():
        for entry in result.failure_summary:
            print(f"  {spec}: {entry['count']} failed steps, the first at step "
                  f"{entry['first_step']} (t={entry['first_t_s']:.3f}s): {entry['message']}")
        if result.solver_messages:
            print(f"  {spec}: the solver wrote {sum(result.solver_messages.values())} lines "
                  f"({len(result.solver_messages)} distinct), kept in metrics.json")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def _add_scenario_robot(parser: argparse.ArgumentParser) -> None:
    """The robot options of a command that runs a scenario (docs/cli.md)."""
    add_robot_arguments(parser.add_argument_group(
        "robot", "the scenario on another robot: paper-hole, trocar-circle, fast-lateral and "
        "joint-limits run on any single arm with a constrained link, the hole halfway along "
        "it, the paths scaled by the arm's reach"), "the scenario's own robot")


def scenario_plan(args: argparse.Namespace):
    """The plan of ``--scenario`` on the robot the robot options ask for (its own robot
    when none is given)."""
    from teleop.experiments.scenarios import SCENARIOS, load_scenario

    if not robot_options_given(args):
        return load_scenario(args.scenario)
    if args.scenario not in SCENARIOS:
        return load_scenario(args.scenario)  # the error naming the scenarios
    return load_scenario(args.scenario, robot_from_arguments(args, SCENARIOS[args.scenario][0]))


def _compare(args: argparse.Namespace) -> int:
    from teleop.experiments.contact_compare import CONTACT_SCENARIOS
    from teleop.loop import LoopConfig

    if args.scenario in CONTACT_SCENARIOS:  # a force law in the loop: its own runner
        defaults = build_parser(registered=False).parse_args(["compare", "--scenario",
                                                              args.scenario])
        return run_contact_compare(args, defaults)
    return _run(collision_choice(args, scenario_plan(args)), args,
                LoopConfig(rate=args.rate or 1000.0, kp=args.kp or LoopConfig.kp,
                           supervisor=supervisor_choice(args),
                           state_observer=args.state_filter),
                plant_choice(args))


def _replay(args: argparse.Namespace) -> int:
    from teleop.experiments.sessions import load_session, session_plan, session_plant
    from teleop.loop import LoopConfig

    session = load_session(args.file)
    header = session.header
    config = LoopConfig(rate=args.rate or header.get("rate_hz", 1000.0),
                        kp=args.kp or header.get("kp", LoopConfig.kp),
                        target_time_constant=header.get("target_time_constant_s", 0.0),
                        supervisor=supervisor_choice(args),
                        state_observer=args.state_filter)
    return _run(collision_choice(args, session_plan(session)), args, config,
                plant_choice(args, session_plant(session)))


def _record(args: argparse.Namespace) -> int:
    from teleop.experiments.contact_compare import refuse_contact_scenario
    from teleop.experiments.sessions import record_plan

    refuse_contact_scenario(args.scenario, "teleop record")
    path = record_plan(collision_choice(args, scenario_plan(args)), args.file,
                       args.rate, args.duration, plant=plant_choice(args))
    print(f"wrote {path}")
    return 0


def _scenarios(args: argparse.Namespace) -> int:
    from teleop.experiments.contact_compare import CONTACT_SCENARIOS
    from teleop.experiments.scenarios import SCENARIOS, load_scenario

    for name in SCENARIOS:
        print(f"{name:<17} {load_scenario(name).description}")
    for name, scenario in CONTACT_SCENARIOS.items():
        print(f"{name:<17} {scenario.description}")
    return 0


def _robots(args: argparse.Namespace) -> int:
    from teleop.robots import BUILTIN_ROBOTS
    from teleop.robots.catalog import example_robot_data_share, installed_urdfs

    print("built-in robots:")
    for name, defaults in BUILTIN_ROBOTS.items():
        frames = defaults.get("ee_frames") or (defaults["ee_frame"],)
        links = ([link for link, _ in defaults["constrained_links"]]
                 if "constrained_links" in defaults else [defaults["constrained_link"]])
        print(f"  {name:<22} EE {', '.join(frames)}; constrained {', '.join(links)}")
    share = example_robot_data_share()
    if share is None:
        print("example-robot-data: not installed (pip install example-robot-data)")
        return 0
    print(f"example-robot-data URDFs (--robot NAME or the path; under {share}):")
    for name, path in installed_urdfs().items():
        print(f"  {name:<22} {path.relative_to(share)}")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from teleop.experiments.bench import (check_json_path, format_table, run_bench, run_scaling,
                                          write_json)
    from teleop.experiments.bench_loop import (format_acceleration_line,
                                               format_acceleration_step_line, format_loop_table,
                                               format_measured_period_line,
                                               run_acceleration_bench, run_loop_bench,
                                               time_acceleration_steps, time_measured_period)

    iterations = 20 if args.quick else args.iterations
    plant = plant_choice(args)  # checked even when --plant is left out
    if args.json:
        check_json_path(args.json)  # before minutes of benchmarking
    results = run_bench(args.robots, args.controllers, iterations=iterations,
                        plant=plant if args.plant else None,
                        allocations=not args.no_allocations)
    if not args.no_scaling:
        results += run_scaling(iterations=max(5, iterations // 5),
                               dofs=(8, 16) if args.quick else (8, 16, 32, 64),
                               holes=(1, 2) if args.quick else (1, 2, 4, 8),
                               allocations=not args.no_allocations)
    print(format_table(results))
    if not args.no_loop:
        loop_timings, step_us = run_loop_bench(duration=1.0 if args.quick else None)
        print()
        print(format_loop_table(loop_timings, step_us))
        print(format_acceleration_line(*run_acceleration_bench(
            duration=1.0 if args.quick else None)))
        print(format_acceleration_step_line(time_acceleration_steps(
            duration=1.0 if args.quick else None)))
        print(format_measured_period_line(time_measured_period(
            duration=1.0 if args.quick else None)))
    for r in results:
        if r.solver_messages:
            print(f"  {r.robot} {r.controller}: the solver wrote "
                  f"{sum(r.solver_messages.values())} lines, kept in solver_messages"
                  + (" of the JSON" if args.json else " (--json FILE writes them)"))
    if args.json:
        write_json(results, args.json)
    return 0


def _sweep(args: argparse.Namespace) -> int:
    return run_sweep_command(args)


if __name__ == "__main__":
    sys.exit(main())
