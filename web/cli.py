"""``teleop web`` / ``python -m web``: the command line of the browser teleoperation UI.

All of ``teleop web``'s options live here, in :data:`COMMAND`, registered as a ``teleop``
subcommand by the entry point ``web = "web.cli:COMMAND"`` of the group ``teleop.commands``
(pyproject.toml): ``teleop`` loads it without importing this layer
(:mod:`teleop.cli.commands`). A robot or scene that cannot be loaded, an address that
cannot be served (a port outside 1-65535, a host that is not one), or any other bad value,
is one line on stderr and exit code 2. Geometry that cannot be drawn as the URDF says (a
mesh that cannot be read) is a warning line, and the UI draws a fallback and says so.
Serving anything but the loopback interface needs ``--token`` and prints a warning saying
what it exposes (docs/design.md section 5.3).
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from typing import Sequence

from teleop.cli.arguments import add_damper_options, bounded, damper_settings, one_line
from teleop.cli.commands import Command
from teleop.cli.plant_options import add_plant_options, plant_choice
from teleop.cli.robot_options import add_robot_arguments, robot_from_arguments, robot_options_given
from teleop.cli.termination import terminations_interrupt
from teleop.limits import MAX_INPUT_TIMEOUT_S, MIN_INPUT_TIMEOUT_S
from teleop.plants.ros2.realtime import LOOP_PRIORITY, MAX_PRIORITY
from teleop.controller_specs import CONTROLLER_HELP
from teleop.loop.task_modes import AUTO, TASK_MODES
from teleop.options import ACCELERATION_LIMITS_HELP, JERK_LIMIT, RATE, WEB

from .access import MIN_TOKEN, check_bind, check_port, is_loopback, make_token, page_url, \
    resolve_host

#: a finite number >= 0

SUMMARY = "browser teleoperation UI (viser) of a built-in robot or any URDF"

SECURITY = """what the server exposes:
Whoever opens the page can move the robot, and read and write scene files in --scene-dir
and recordings in --record-dir (file names only, nothing outside those folders). The
server listens on this machine only (127.0.0.1) unless --host says otherwise; another
address needs --token. The page must be opened at the address printed at start (it
carries the token, random per launch unless --token gives it), and a websocket whose
Origin is not the page's own is refused: no other site open in the browser can connect.
From another machine, prefer an SSH tunnel to the loopback server, same port both ends:
  ssh -L 8080:127.0.0.1:8080 robot-pc   then open the printed address there
Network masters (--input udp:PORT) must tag every datagram with the key printed at start
(or --input-key FILE)."""


#: ``--input-timeout``: milliseconds within the table's bounds
INPUT_TIMEOUT_MS = bounded(float, 1e3 * MIN_INPUT_TIMEOUT_S, 1e3 * MAX_INPUT_TIMEOUT_S, unit="ms")
LOOP_PRIORITY_TYPE = bounded(int, 0, MAX_PRIORITY)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """``teleop web``'s options, added to ``parser``."""
    robot = parser.add_argument_group("robot")
    add_robot_arguments(robot, "sda10f, or the robot of --scene")
    robot.add_argument("--scene", metavar="FILE",
                       help="open a scene saved from the UI (its robot, constraints, target, "
                            "controllers, gain, damping, rate); the other robot options must "
                            "not be given with it (default: none)")

    control = parser.add_argument_group("control")
    control.add_argument("--controller", default="cjm",
                         help=f"controller of the robot: {CONTROLLER_HELP}")
    control.add_argument("--ghost", metavar="CONTROLLER",
                         help="controller of a second robot (the ghost) driven from the same "
                              "target, drawn beside the main one; a scene's own wins "
                              "(default: no second robot)")
    RATE.add_to(control, 1000.0)
    control.add_argument("--task-mode", choices=(AUTO, *TASK_MODES), default=AUTO,
                         help="what the target asks of each end effector (docs/design.md "
                              "section 20): the full pose, position and roll about the tool "
                              "axis, or position only; auto: position and roll on an arm with "
                              "a port, else the full pose; a scene's own wins (default: auto)")
    control.add_argument("--acceleration-limits", action=argparse.BooleanOptionalAction,
                         default=True, help=ACCELERATION_LIMITS_HELP)
    JERK_LIMIT.add_to(control, left_out="none")

    add_plant_options(parser.add_argument_group(
        "plant (docs/design.md section 17)", "what the loops run on; a robot over ROS 2 is "
        "the main one (no ghost)"), WEB, "kinematic")

    collisions = parser.add_argument_group("collision avoidance (docs/design.md section 18)")
    collisions.add_argument("--collisions", action=argparse.BooleanOptionalAction, default=None,
                            help="the controllers keep the robot's link pairs and the obstacles "
                                 "placed in the page at least the safety distance apart "
                                 "(default: on; a scene's own setting wins)")
    collisions.add_argument("--self-collision", action=argparse.BooleanOptionalAction,
                            default=None,
                            help="check the robot's links against each other, not only against "
                                 "the obstacles (default: on for a robot with several arms)")
    add_damper_options(collisions)

    files = parser.add_argument_group("files (the page reads and writes only these folders)")
    files.add_argument("--scene-dir", default="scenes", metavar="DIR",
                       help="folder the page saves scenes to and loads them from, by file "
                            "name (created on the first save)")
    files.add_argument("--record-dir", default="sessions", metavar="DIR",
                       help="folder the page writes recorded sessions to (created on the "
                            "first recording)")

    devices = parser.add_argument_group("input devices (docs/inputs.md)")
    devices.add_argument("--input", action="append", metavar="SOURCE",
                         help="what drives an end effector besides the gizmo: udp:PORT (a "
                              "network master, bound to --host), ros2:NAMESPACE (a CRTK master "
                              "on ROS 2: servo_cp in, servo_cf out, docs/ros2.md) or "
                              "spacemouse; each takes the "
                              "next EE, or the one named after @ (udp:9870@right); repeatable "
                              "(default: the gizmo only)")
    devices.add_argument("--input-key", metavar="FILE",
                         help="file holding the key of the network masters (hex digits, "
                              "16-64 bytes; e.g. `python -c \"import secrets; "
                              "print(secrets.token_hex(32))\" > key`): every datagram must "
                              "carry its HMAC (default: a key drawn at start and printed)")
    devices.add_argument("--input-timeout", type=INPUT_TIMEOUT_MS, default="100", metavar="MS",
                         help="a network master silent this long (ms, 5-5000) is released: "
                              "its target holds and the robot stops (default: 100)")
    server = parser.add_argument_group("server")
    server.add_argument("--host", default="127.0.0.1",
                        help="address to bind; the UI commands a robot, so only this machine "
                             "by default. Any other address (0.0.0.0: every interface) "
                             "needs --token and prints a warning")
    server.add_argument("--port", default="8080", help="port to serve the UI on (1-65535)")
    server.add_argument("--loop-priority", type=LOOP_PRIORITY_TYPE, default=LOOP_PRIORITY,
                        metavar="N",
                        help="SCHED_FIFO priority of the control thread, the server's own "
                             "threads at 1 while it holds it (docs/design.md 5.3); 0: "
                             "ordinary scheduling; without the privilege (root, CAP_SYS_NICE, "
                             "ulimit -r) they stay ordinary and the status says so; over ROS 2 "
                             "the plant's --realtime-priority decides "
                             f"(default: {LOOP_PRIORITY})")
    server.add_argument("--token", metavar="TOKEN",
                        help=f"secret every page must present (at least {MIN_TOKEN} characters "
                             "of A-Z a-z 0-9 _ - . ~, or 'auto' for a random one); required "
                             "when --host is not a loopback address; open the address printed "
                             "at start. It travels unencrypted: across an untrusted network use "
                             "an SSH tunnel (default: a random one per launch)")


def _load(args: argparse.Namespace):
    """The robot and the scene (or None) the options ask for."""
    if args.scene is None:
        return robot_from_arguments(args, "sda10f"), None
    given = robot_options_given(args)
    if given:
        raise ValueError(f"--scene sets the robot: drop {', '.join(given)}")
    from web.scene import read_scene_file, robot_from_dict

    scene = read_scene_file(args.scene)
    if not isinstance(scene, dict):
        raise ValueError(f"scene file {args.scene!r} does not hold a JSON object")
    return robot_from_dict(scene.get("robot")), scene


def _address(args: argparse.Namespace, prog: str) -> tuple[int, str | None]:
    """The port and token to serve with (a random one per launch unless ``--token``
    gives it); ``ValueError`` for a port or host that cannot be served, a bad token, or a
    host beyond loopback without ``--token`` (then a warning line is printed)."""
    port = check_port(args.port)
    addresses = resolve_host(args.host)
    check_bind(addresses, port)
    if not is_loopback(addresses):
        if args.token is None:
            raise ValueError(f"--host {args.host} serves the UI beyond this machine: give "
                             "--token TOKEN (or --token auto), or use an SSH tunnel to "
                             "127.0.0.1")
        print(f"{prog}: warning: listening on {args.host} ({', '.join(addresses)}): anyone "
              "who can reach this port and has the token can move the robot and read and "
              f"write files in {args.scene_dir} and {args.record_dir}; the token and the "
              "page travel unencrypted (an SSH tunnel to 127.0.0.1 avoids both)"
              + ("; the --input udp ports take only datagrams carrying the key's HMAC"
                 if any(spec.startswith("udp:") for spec in args.input or ()) else ""),
              file=sys.stderr)
    return port, make_token("auto" if args.token is None else args.token)


def _plant(args: argparse.Namespace) -> dict:
    """The plant keywords of :func:`web.ui.run_server` the options ask for (each value
    checked by its option's validator, :mod:`teleop.plants.options`); ``ValueError``
    naming an option the plant does not take."""
    choice = plant_choice(args)
    return {"plant": choice.kind, "plant_settings": choice.settings,
            "wall_stiffness": choice.wall_stiffness, "ros2_settings": choice.ros2}


def _collisions(args: argparse.Namespace) -> dict:
    """The collision keywords of :func:`web.ui.run_server` the options ask for, in SI
    units (values the avoidance cannot take together, such as d_i <= d_s or a damper
    unstable at --rate, are its ``ValueError``: one line, exit 2)."""
    settings = {name: value for name, (_, value) in damper_settings(args).items()}
    if args.self_collision is not None:
        settings["self_collision"] = args.self_collision
    return {"collisions": args.collisions is not False, "collision_settings": settings}


def _ee_index(name: str, frames: list[str], default: int, spec: str) -> int:
    """The EE an ``--input`` names after ``@`` (its index, frame or short name as the page
    shows it), else the ``default``; ``ValueError`` for one the robot does not have."""
    from web.ui.core import short_names

    names = {**{str(i): i for i in range(len(frames))},
             **{frame: i for i, frame in enumerate(frames)},
             **{short: frames.index(frame) for frame, short in short_names(tuple(frames)).items()}}
    index = names.get(name) if name else default
    if index is None or index >= len(frames):
        raise ValueError(f"--input {spec}: no end effector {name or default} (this robot's: "
                         f"{', '.join(frames)})")
    return index


def _input_key(args: argparse.Namespace, prog: str) -> bytes | None:
    """The network masters' key: ``--input-key``'s, else one drawn now and printed (None
    without a udp input); ``ValueError`` naming a key file that cannot be used."""
    from teleop.inputs import new_key, read_key_file

    if not any(spec.startswith("udp:") for spec in args.input or ()):
        if args.input_key is not None:
            raise ValueError("--input-key needs an --input udp:PORT")
        return None
    if args.input_key is not None:
        return read_key_file(args.input_key)
    key = new_key()
    print(f"{prog}: network master key {key.hex()} (the master tags every datagram with "
          "it; --input-key FILE to give one)", flush=True)
    return key


def _ros2_master(namespace: str, ee: int, domain: int | None, spec: str):
    """A CRTK master on ROS 2 (``--input ros2:/MTMR``): its ``servo_cp`` drives EE ``ee``,
    the feedback goes out on its ``servo_cf`` (docs/ros2.md); ``ValueError`` without the
    ros2 extra or for a namespace ROS 2 refuses."""
    try:
        from teleop.inputs.ros2_master import Ros2Master
    except ImportError as error:
        raise ValueError(f"--input {spec} needs the ros2 extra (pip install '.[ros2]'): "
                         f"{error}") from None
    return Ros2Master(namespace, ee=ee, domain=domain)


def _inputs(args: argparse.Namespace, robot, prog: str) -> list:
    """The input sources ``--input`` asks for, each on its EE; ``ValueError`` for a bad
    one or a port that cannot be bound. A SpaceMouse that is not there is one warning
    line: the UI runs without it."""
    from teleop.inputs import InputSource, UdpMaster

    key = _input_key(args, prog)
    sources: list[InputSource] = []
    try:
        for index, spec in enumerate(args.input or ()):
            kind, _, name = spec.partition("@")
            ee = _ee_index(name, list(robot.ee_frames), index, spec)
            if kind == "spacemouse":
                from teleop.inputs.spacemouse import SpaceMouse
                if any(isinstance(source, SpaceMouse) for source in sources):
                    raise ValueError(f"--input {spec}: one SpaceMouse only (it would drive "
                                     "both end effectors)")
                try:
                    sources.append(SpaceMouse.open(ee))
                except ValueError as error:
                    print(f"{prog}: warning: --input spacemouse: {one_line(error)}; the UI "
                          "runs without it", file=sys.stderr)
            elif kind.startswith("udp:"):
                sources.append(UdpMaster(check_port(kind[4:]), host=args.host, ee=ee,
                                         max_age=args.input_timeout / 1e3, key=key))
            elif kind.startswith("ros2:"):
                sources.append(_ros2_master(kind[5:], ee, args.ros_domain, spec))
            else:
                raise ValueError(f"--input {spec}: expected udp:PORT, ros2:NAMESPACE or "
                                 "spacemouse")
    except ValueError:
        for source in sources:
            source.close()
        raise
    return sources


def run(args: argparse.Namespace, prog: str) -> int:
    """Serve the UI the options ``args`` ask for until Ctrl-C; 2 (and one line on stderr,
    naming ``prog``) when it cannot start."""
    try:
        plant = _plant(args)
        collisions = _collisions(args)
        port, token = _address(args, prog)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            robot, scene = _load(args)
        notes = [one_line(w.message) for w in caught]
        for note in notes:  # e.g. meshes not found: the UI draws a fallback and says so
            print(f"{prog}: warning: {note}", file=sys.stderr)
        from web.ui import run_server

        inputs = _inputs(args, robot, prog)
        try:
            server, app, control, ui = run_server(robot, host=args.host, port=port,
                                                  controller=args.controller, ghost=args.ghost,
                                                  rate=args.rate, record_dir=args.record_dir,
                                                  scene_dir=args.scene_dir, scene=scene,
                                                  notes=notes, token=token, **plant,
                                                  acceleration_limits=args.acceleration_limits,
                                                  jerk_limit=args.jerk_limit,
                                                  task_mode=args.task_mode,
                                                  **collisions, inputs=inputs,
                                                  input_timeout=args.input_timeout / 1e3,
                                                  realtime_priority=args.loop_priority)
        except BaseException:
            for source in inputs:
                source.close()
            raise
    except (OSError, ValueError) as error:  # no such URDF/scene, bad frame / q_home / spec, port
        print(f"{prog}: {one_line(error)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C while loading
        return 130
    try:
        ghost = app.robots.specs.get("ghost")
        print(f"{prog}: {robot.name} on {page_url(args.host, server.get_port(), token)} "
              f"(controller {app.robots.specs['main']}{', ghost ' + ghost if ghost else ''})"
              f"{', on the ' + app.plant.describe() if app.plant.kind != 'kinematic' else ''}"
              + "".join(f", input {device.source.name} on {robot.ee_frames[device.source.ee]}"
                        for device in app.devices) + "; Ctrl-C stops", flush=True)
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:  # the robot first: its one commander stopped, then zeros on the wire
        control.stop()
        if app.ros2 is not None:
            app.ros2.close()
        ui.stop()
        app.devices.close()
        server.stop()
    return 0


COMMAND = Command(SUMMARY, add_arguments, run, epilog=SECURITY)


def build_parser(prog: str = "teleop web") -> argparse.ArgumentParser:
    """``teleop web``'s parser, standing alone (``python -m web``)."""
    return COMMAND.parser(prog)


def main(argv: Sequence[str] | None = None, prog: str = "teleop web") -> int:
    """``prog ARGV``: parse the options and :func:`run`."""
    with terminations_interrupt():  # SIGTERM unwinds as Ctrl-C: a robot gets its zeros
        return run(build_parser(prog).parse_args(argv), prog)


if __name__ == "__main__":
    sys.exit(main())
