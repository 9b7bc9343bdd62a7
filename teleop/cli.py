"""Command line: ``teleop bench`` (more subcommands come with the closed loop and the UI)."""

from __future__ import annotations

import argparse
import sys
from typing import Sequence


def _csv(text: str) -> list[str]:
    return [item.strip() for item in text.split(",") if item.strip()]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="teleop",
        description="Operational-space teleoperation under kinematic constraints (CJM, QP).")
    commands = parser.add_subparsers(dest="command", required=True)

    bench = commands.add_parser("bench", help="one-step time of each controller on each robot")
    bench.add_argument("--robots", type=_csv, default=["sda10f", "ur5_instrument"],
                       help="comma-separated robot names (default: both built-ins)")
    bench.add_argument("--controllers", type=_csv,
                       default=["cjm", "cjm:general", "qp:proxqp", "qp:daqp", "qp:osqp"],
                       help="comma-separated controller specs")
    bench.add_argument("--iterations", type=int, default=2000, help="timed steps per controller")
    bench.add_argument("--quick", action="store_true", help="a few iterations (CI smoke run)")
    bench.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "bench":
        from .bench import format_table, run_bench, write_json

        iterations = 20 if args.quick else args.iterations
        if iterations < 1:
            print("teleop bench: --iterations must be >= 1", file=sys.stderr)
            return 2
        try:
            results = run_bench(args.robots, args.controllers, iterations=iterations)
        except ValueError as error:
            print(f"teleop bench: {error}", file=sys.stderr)
            return 2
        print(format_table(results))
        if args.json:
            write_json(results, args.json)
        return 0
    return 2


if __name__ == "__main__":
    sys.exit(main())
