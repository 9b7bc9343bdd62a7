"""Command line: ``teleop compare | replay | record | bench | scenarios``."""

from __future__ import annotations

import argparse
import sys
from typing import Sequence

DEFAULT_CONTROLLERS = "cjm,qp:proxqp,qp:daqp,qp:osqp,mink:daqp"


def _csv(text: str) -> list[str]:
    items = [item.strip() for item in text.split(",") if item.strip()]
    if not items:
        raise argparse.ArgumentTypeError("expected a comma-separated list")
    return items


def _positive(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--controllers", type=_csv, default=_csv(DEFAULT_CONTROLLERS),
                        help=f"comma-separated controllers (default {DEFAULT_CONTROLLERS}); "
                             "cjm[:general|:paper], qp:<solver>, mink:<solver>")
    parser.add_argument("--rate", type=_positive, help="control rate in Hz (default 1000)")
    parser.add_argument("--duration", type=_positive, help="seconds to run (default: all)")
    parser.add_argument("--out", default="out", help="output directory (default ./out)")
    parser.add_argument("--no-plots", action="store_true", help="metrics only")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="teleop",
        description="Operational-space teleoperation under kinematic constraints (CJM, QP, mink).")
    commands = parser.add_subparsers(dest="command", required=True)

    compare = commands.add_parser("compare", help="run controllers on a scripted scenario")
    compare.add_argument("--scenario", required=True, help="scenario name (see 'teleop scenarios')")
    _add_run_options(compare)

    replay = commands.add_parser("replay", help="replay a recorded session through controllers")
    replay.add_argument("file", help="session file (JSON lines, see README)")
    _add_run_options(replay)

    record = commands.add_parser("record", help="write a scenario's operator input as a session")
    record.add_argument("--scenario", required=True)
    record.add_argument("--rate", type=_positive, default=1000.0)
    record.add_argument("--duration", type=_positive)
    record.add_argument("file", help="session file to write")

    commands.add_parser("scenarios", help="list the scenarios")

    web = commands.add_parser("web", help="browser teleoperation UI (viser)")
    web.add_argument("--robot", default="sda10f",
                     help="sda10f, ur5_instrument, or a URDF path (default sda10f)")
    web.add_argument("--host", default="127.0.0.1",
                     help="address to bind (default 127.0.0.1: this machine only; the UI "
                          "commands a robot, open it wider only on purpose)")
    web.add_argument("--port", type=int, default=8080)
    web.add_argument("--controller", default="cjm", help="main robot's controller")
    web.add_argument("--ghost", help="controller of a translucent second robot (side by side)")
    web.add_argument("--rate", type=_positive, default=1000.0, help="control rate (Hz)")
    web.add_argument("--record-dir", default="sessions", help="where recordings are written")
    web.add_argument("--ee-frame", help="EE frame (URDF robots)")
    web.add_argument("--constrained-link", help="constrained link (URDF robots)")

    bench = commands.add_parser("bench", help="one-step time of each controller on each robot")
    bench.add_argument("--robots", type=_csv, default=["sda10f", "ur5_instrument"])
    bench.add_argument("--controllers", type=_csv,
                       default=_csv("cjm,cjm:general,qp:proxqp,qp:daqp,qp:osqp,mink:daqp,mink:proxqp"))
    bench.add_argument("--iterations", type=int, default=2000, help="timed steps per controller")
    bench.add_argument("--quick", action="store_true", help="a few iterations (CI smoke run)")
    bench.add_argument("--no-scaling", action="store_true", help="skip the generated-chain scaling")
    bench.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    return parser


def _run(plan, args, config) -> int:
    from teleop.experiments.compare import compare, format_table, metrics_document, write_outputs

    duration = args.duration or plan.duration
    results = compare(plan, args.controllers, config, duration, progress=not args.quiet)
    paths = write_outputs(plan, results, config, duration, args.out, plots=not args.no_plots)
    document = metrics_document(plan, results, config, duration)
    print(f"{plan.name}: {plan.description} ({duration:g} s at {config.rate:g} Hz)")
    print(format_table(document))
    for spec, result in results.items():
        if result.failure_messages:
            print(f"  {spec}: {len(result.failure_messages)}+ failed steps, first {result.failure_messages[0]}")
    print("wrote " + ", ".join(str(p) for p in paths))
    return 0


def _web(args) -> int:
    import time

    from web.ui import run_server

    from teleop.robots import load_robot

    robot = load_robot(args.robot, ee_frame=args.ee_frame, constrained_link=args.constrained_link)
    server, app, control, ui = run_server(robot, host=args.host, port=args.port,
                                          controller=args.controller, ghost=args.ghost,
                                          rate=args.rate, record_dir=args.record_dir)
    print(f"teleop web: {robot.name} on http://{args.host}:{server.get_port()} "
          f"(controller {args.controller}{', ghost ' + args.ghost if args.ghost else ''}); "
          "Ctrl-C stops", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:
        ui.stop()
        control.stop()
        server.stop()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return _dispatch(args)
    except ValueError as error:  # bad scenario, controller, file: one clear line
        print(f"teleop {args.command}: {error}", file=sys.stderr)
        return 2


def _dispatch(args) -> int:
    from teleop.loop import LoopConfig

    if args.command == "web":
        return _web(args)
    if args.command == "scenarios":
        from teleop.experiments.scenarios import SCENARIOS, load_scenario

        for name in SCENARIOS:
            print(f"{name:<15} {load_scenario(name).description}")
        return 0
    if args.command == "compare":
        from teleop.experiments.scenarios import load_scenario

        plan = load_scenario(args.scenario)
        return _run(plan, args, LoopConfig(rate=args.rate or 1000.0))
    if args.command == "replay":
        from teleop.experiments.sessions import load_session, session_plan

        session = load_session(args.file)
        header = session.header
        config = LoopConfig(rate=args.rate or header.get("rate_hz", 1000.0),
                            kp=header.get("kp", 20.0),
                            target_time_constant=header.get("target_time_constant_s", 0.0))
        return _run(session_plan(session), args, config)
    if args.command == "record":
        from teleop.experiments.scenarios import load_scenario
        from teleop.experiments.sessions import record_plan

        path = record_plan(load_scenario(args.scenario), args.file, args.rate, args.duration)
        print(f"wrote {path}")
        return 0
    if args.command == "bench":
        from teleop.experiments.bench import format_table, run_bench, run_scaling, write_json

        iterations = 20 if args.quick else args.iterations
        if iterations < 1:
            raise ValueError("--iterations must be >= 1")
        results = run_bench(args.robots, args.controllers, iterations=iterations)
        if not args.no_scaling:
            results += run_scaling(iterations=max(5, iterations // 5),
                                   dofs=(8, 16) if args.quick else (8, 16, 32, 64),
                                   holes=(1, 2) if args.quick else (1, 2, 4, 8))
        print(format_table(results))
        if args.json:
            write_json(results, args.json)
        return 0
    return 2


if __name__ == "__main__":
    sys.exit(main())
