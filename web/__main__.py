"""``python -m web``: the same as ``teleop web``."""

import sys

from web.cli import main

sys.exit(main(prog="python -m web"))
