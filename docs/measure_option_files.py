"""The files a plant's options are written in (issue 34 item 6): how many files a new plant,
or a new option of one, touches.

For each plant's options (the ROS 2 robot's, the MuJoCo plant's, the imperfect plant's),
list the non-test Python files of the package (``teleop``, ``web``, ``controllers``,
``constraints``; not ``tests``, ``docs`` or ``examples``) that spell one of them out as a
front end does: the command-line option (``--joint-states``), the parsed attribute
(``args.joint_states``) or the name quoted (``"joint_states"``, a spec's or a keyword's
field). The file declaring the option and the plant that reads it are counted too: they
are the floor.

Run:  python docs/measure_option_files.py [--list]
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("teleop", "web", "controllers", "constraints")

#: each plant and the fields of its options (the command line's names, underscored)
PLANTS = {
    "ros2": ("joint_states", "command_topic", "command_joints", "crtk", "ros_domain",
             "realtime_priority"),
    "mujoco": ("payload", "coulomb_friction", "viscous_friction", "physics_rate",
               "servo_bandwidth", "interface_limits", "interface_jerk_limit",
               "wall_stiffness"),
    "imperfect": ("encoder_noise", "latency", "joint_time_constant", "calibration_error"),
}


def pattern(names: tuple[str, ...]) -> re.Pattern[str]:
    """``--a-b``, ``args.a_b`` or ``"a_b"`` / ``'a_b'`` for any of ``names``."""
    words = "|".join(names)
    dashed = "|".join(name.replace("_", "-") for name in names)
    return re.compile(rf"--(?:{dashed})\b|args\.(?:{words})\b|[\"'](?:{words})[\"']")


def files_naming(names: tuple[str, ...]) -> list[Path]:
    """The package's non-test Python files that spell out one of ``names``."""
    found = pattern(names)
    return sorted(path.relative_to(ROOT) for package in PACKAGES
                  for path in (ROOT / package).rglob("*.py")
                  if found.search(path.read_text(encoding="utf-8")))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="list the files too")
    args = parser.parse_args()
    for plant, names in PLANTS.items():
        files = files_naming(names)
        print(f"{plant}: {len(files)} files")
        if args.list:
            for path in files:
                print(f"  {path}")


if __name__ == "__main__":
    main()
