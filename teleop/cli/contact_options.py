"""``teleop compare`` on a contact scenario (``--scenario palpation --plant mujoco``,
docs/cli.md, docs/design.md section 21.4): its own options (the force/torque sensor's
noise, the force filter) and the run. A contact scenario takes the controllers, the rate,
the duration, the outputs, the plant's options, the acceleration and jerk limits and the
seed; any other compare option given is refused by name (it would be ignored)."""

from __future__ import annotations

import argparse

from teleop.plants.options import PLANT_OPTIONS

from .arguments import bounded

#: The largest sensor noise the command takes (N, standard deviation).
MAX_SENSOR_NOISE_N = 10.0
#: The largest force-filter cut-off the command takes (Hz; the Nyquist frequency of the
#: rate is checked by the filter).
MAX_FORCE_FILTER_HZ = 1000.0

sensor_noise = bounded(float, 0.0, MAX_SENSOR_NOISE_N, unit="N")
force_filter = bounded(float, 0.0, MAX_FORCE_FILTER_HZ, inclusive_minimum=False, unit="Hz")

#: The compare options a contact scenario uses (argparse destinations): its own, the
#: run's and every option of the mujoco plant (:data:`PLANT_OPTIONS`).
CONTACT_USES = frozenset({
    "command", "run_command", "scenario", "controllers", "rate", "duration", "out", "no_plots",
    "quiet", "acceleration_limits", "jerk_limit", "seed", "plant", "sensor_noise",
    "force_filter", *(option.name for option in PLANT_OPTIONS if "mujoco" in option.plants)})


def add_contact_options(parser: argparse.ArgumentParser) -> None:
    """The options of the contact scenarios (``teleop scenarios`` lists them)."""
    group = parser.add_argument_group(
        "contact scenarios", "palpation: the tool-frame force law on the mujoco plant "
        "(docs/design.md section 21)")
    group.add_argument("--sensor-noise", type=sensor_noise, default=0.0, metavar="N",
                       help="std of the white noise on every component of the tool's "
                       f"force/torque sensor (N, N m), at most {MAX_SENSOR_NOISE_N:g}")
    group.add_argument("--force-filter", type=force_filter, metavar="HZ",
                       help="cut-off of the force law's two-section low-pass filter on the "
                       "sensed wrench, below half the rate; the stability check takes its "
                       "lag (default: none)")


def unused_options(args: argparse.Namespace, defaults: argparse.Namespace) -> list[str]:
    """The options given (unlike ``defaults``) that a contact scenario does not use."""
    return [f"--{name.replace('_', '-')}" for name, value in sorted(vars(args).items())
            if name not in CONTACT_USES and value != getattr(defaults, name, None)]


def run_contact_compare(args: argparse.Namespace, defaults: argparse.Namespace) -> int:
    """Every controller through the contact scenario ``args.scenario``: the table, then
    ``contact_metrics.json`` (and ``contact_force.png``) into ``--out``; ``ValueError``
    (one line) for an option it would ignore, a plant without a sensor, a bad setting."""
    from teleop.experiments.contact_compare import (compare_contact, format_contact_table,
                                                    write_contact_outputs)
    from teleop.experiments.compare import output_directory

    from .plant_options import plant_choice

    unused = unused_options(args, defaults)
    if unused:
        raise ValueError(f"{', '.join(unused)} do{'es' * (len(unused) == 1)} not apply to the "
                         f"contact scenario {args.scenario}")
    output_directory(args.out)  # before the runs
    plant = plant_choice(args)
    document, results = compare_contact(
        args.scenario, args.controllers, plant, args.rate, args.duration, args.sensor_noise,
        args.seed, args.acceleration_limits, args.jerk_limit, args.force_filter,
        progress=not args.quiet)
    paths = write_contact_outputs(document, results, args.out, plots=not args.no_plots)
    noise = (f"sensor noise {args.sensor_noise:g} N" if args.sensor_noise
             else "no sensor noise")
    filtered = (f"force filter {args.force_filter:g} Hz" if args.force_filter is not None
                else "no force filter")
    print(f"{args.scenario}: {document['description']} ({document['duration_s']:g} s at "
          f"{args.rate:g} Hz; {plant.describe()}; {noise}, {filtered})")
    print(format_contact_table(document))
    print("wrote " + ", ".join(str(path) for path in paths))
    return 0
