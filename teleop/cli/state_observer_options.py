"""The joint-state observer's command-line option (docs/cli.md, docs/design.md 5.6)."""

from __future__ import annotations

import argparse

from teleop.loop.state_observer import StateObserverConfig


def _mode(text: str) -> StateObserverConfig:
    """``kalman``, ``off`` or a gain in (0, 1] (argparse type)."""
    if text == "kalman":
        return StateObserverConfig()
    if text == "off":
        return StateObserverConfig(enabled=False)
    try:
        return StateObserverConfig(gain=float(text))
    except ValueError as error:
        raise argparse.ArgumentTypeError(
            f"expected kalman, off or a gain in (0, 1], got {text!r} ({error})") from None


def add_state_observer_option(parser: argparse.ArgumentParser) -> None:
    """``--state-filter kalman|off|GAIN`` (default: kalman)."""
    parser.add_argument("--state-filter", type=_mode, default="kalman",  # argparse parses it
                        metavar="kalman|off|GAIN",
                        help="the joint-state observer between the encoders and the "
                        "controller and supervisor (docs/design.md section 5.6): kalman, the "
                        "Kalman gain of the declared encoder noise (raw without noise); off, "
                        "the encoders raw; or a fixed gain in (0, 1] (default: kalman)")
