"""The bounds and rates of the browser session: what the operator may ask, how often the
app measures (docs/design.md section 5)."""

from __future__ import annotations

from constraints.validation import as_number

#: the operator's target and moved geometry are smoothed with this time constant (s)
DEFAULT_SMOOTHING = 0.05
#: EE speed caps of the operator's command: a dragged gizmo jumps by centimetres, and at
#: these speeds the robots stay within their joint-velocity limits (docs/design.md
#: section 5.3)
MAX_LINEAR_SPEED = 0.05  # m/s
MAX_ANGULAR_SPEED = 0.5  # rad/s
#: seconds of history kept for the live plots
HISTORY_SECONDS = 10.0
#: history samples per second: the measures (constraint errors, EE error, ...) are taken
#: on these ticks only; every other tick computes just what the controller needs
HISTORY_RATE = 50.0
#: the motion scale is a number in (0, MAX_MOTION_SCALE]
MAX_MOTION_SCALE = 10.0
#: a point given in a link's coordinates is at most this far from its origin (m)
MAX_LINK_POINT = 2.0
#: the ghost's offset from the main robot is at most this long (m)
MAX_GHOST_OFFSET = 5.0
#: an EE target (or a constraint's goal) is refused farther than this from where the EE
#: (or the constraint) is now (m): no arm reaches farther, and a number such as 1e300
#: would otherwise reach the controllers as a twist of that size
MAX_TARGET_DISTANCE = 2.0
#: the CJM's constant damping lambda is at most this (the slider offers 0-0.2; at 1 the
#: damped inverse barely moves the robot)
MAX_DAMPING = 1.0
#: the control rate (Hz) is between these
MIN_RATE, MAX_RATE = 50.0, 5000.0
#: the EE is "on target" within this distance (m); it does not follow its target when it
#: approaches it at less than FOLLOWING of the commanded speed, or moves at less than
#: STALLED_SPEED (m/s) when the command is that slow
ON_TARGET = 1e-3
FOLLOWING = 0.2
STALLED_SPEED = 1e-3


def checked_rate(rate: float, what: str = "rate") -> float:
    """``rate`` (Hz) if it is a number in [MIN_RATE, MAX_RATE], else ``ValueError``."""
    rate = as_number(rate, what)
    if not MIN_RATE <= rate <= MAX_RATE:
        raise ValueError(f"{what} must be between {MIN_RATE:g} and {MAX_RATE:g} Hz, "
                         f"got {rate:g}")
    return rate

#: How far (rad, every joint) a scene's configuration may lie from where a real robot (the
#: ros2 plant) is for the page to open it: its constraints were placed there, and the robot
#: cannot jump (encoder noise and a settled servo are far below it).
ROS2_SCENE_TOLERANCE = 0.01
