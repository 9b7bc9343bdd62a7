"""``python -m web``: the same as ``teleop web``."""

import sys

from teleop.cli import main

sys.exit(main(["web", *sys.argv[1:]]))
