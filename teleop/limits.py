"""The one table of limits: the largest rates, durations, sizes, latencies, noise, gains,
stiffnesses and counts any input may carry.

Every entry point (the Python API, the CLI, session and scene files, sweep specs) checks
its input against these, so that no input makes a run allocate without end, never finish
or leave the physics stable in name only (docs/design.md section 15.6; the table for
users: docs/sessions.md, "Limits"). Each bound is far beyond any real use; the line above
it says why. The bounds of what constraints and obstacles carry are checked where those
are built, in the layer below: they are written in :mod:`constraints.limits` and listed
here with the rest.
"""

from __future__ import annotations

from constraints.limits import (  # noqa: F401 (listed here: the one table)
    MAX_COLLISION_DISTANCE_M,
    MAX_CONSTRAINT_GAIN,
    MAX_OBSTACLE_SIZE_M,
    MAX_OBSTACLES,
    MAX_POSITION_M,
    MAX_RESPONSE_TIME_S,
    MAX_SPEED_M_S,
    MAX_TISSUE_DAMPING,
    MAX_TISSUE_STIFFNESS,
)

#: A force setpoint's largest component (N): five times the 1 N of palpation
#: (docs/design.md 21.4), a firm press on soft tissue.
MAX_FORCE_SETPOINT_N = 5.0

#: Control rate (Hz). Robot joint interfaces run at 1-8 kHz; at 1e12 Hz a simulated second
#: would never finish.
MAX_RATE_HZ = 10_000.0

#: Simulated time (s) of a run, a recording or a session: an hour, longer than any
#: teleoperated procedure recorded to replay.
MAX_DURATION_S = 3_600.0

#: Control periods of one run: each tick keeps a record (1.5 kB with one hole, measured),
#: so a run holds at most about 1.5 GB; 1000 s at 1 kHz.
MAX_STEPS = 1_000_000

#: Command latency (s): a command a second old is no longer teleoperation.
MAX_LATENCY_S = 1.0

#: Command latency in control periods: :data:`MAX_LATENCY_S` at :data:`MAX_RATE_HZ` (each
#: period in flight holds one queued command).
MAX_LATENCY_PERIODS = int(MAX_LATENCY_S * MAX_RATE_HZ)

#: Standard deviation of the simulated encoder noise (rad): 0.1 rad (5.7 degrees) is
#: thousands of counts of any joint encoder.
MAX_ENCODER_NOISE_RAD = 0.1

#: Standard deviation of the simulated calibration error of every joint placement: 5 cm
#: and 0.2 rad (11 degrees) per axis, far beyond any robot that was ever calibrated
#: (docs/design.md section 15.1, "Calibration error").
MAX_CALIBRATION_POSITION_STD_M = 0.05
MAX_CALIBRATION_ROTATION_STD_RAD = 0.2

#: Time constant (s) of the simulated joint velocity response, and of the target
#: smoothing: a joint or a filter slower than a second is not following its command.
MAX_TIME_CONSTANT_S = 1.0

#: The CJM's damped-least-squares damping (paper eq 35), in units of the constrained
#: Jacobian's singular values (order 1 for an arm, m and rad): 1 already damps every
#: direction of such an arm by half or more; the UI's slider stops at 0.2.
MAX_DAMPING = 1.0

#: Timed steps per controller in ``teleop bench``: 1e6 steps of 50 us is under a minute.
MAX_BENCH_ITERATIONS = 1_000_000

#: The stiffest abdominal wall a plant takes (N/m): every hole's ``tissue_stiffness``.
MAX_WALL_STIFFNESS = MAX_TISSUE_STIFFNESS

#: The pose-error gain kp (1/s): kp dt = 1 at the fastest rate closes the error in one
#: period; the default is 20.
MAX_POSE_GAIN = 10_000.0

#: The physics plant (docs/design.md section 17.1): a payload (kg) at each end effector
#: beyond any arm's rating; physics steps per second (Hz), from twice the 1 kHz loop to
#: ten times the fastest useful; the servos' natural frequency (Hz) above any joint's
#: drive; friction and damping (N m, N m s/rad) beyond any joint's.
MAX_PAYLOAD_KG = 100.0
MIN_PHYSICS_RATE_HZ = 2_000.0
MAX_PHYSICS_RATE_HZ = 1e5
MAX_SERVO_BANDWIDTH_HZ = 200.0
MAX_JOINT_FRICTION = 1e4

#: The physics plant's interface jerk limit (rad/s^3, docs/design.md section 17.1): a
#: Franka's joints refuse commands beyond 3,750-10,000 rad/s^3 (libfranka's
#: ``kMaxJointJerk``); 1e8 is a jerk no drive could follow.
MAX_INTERFACE_JERK = 1e8

#: A controller's jerk limit (rad/s^3), the same bound as the interface's it is kept for.
MAX_JERK = MAX_INTERFACE_JERK

#: Bytes of a sweep spec file: a hand-written spec is a few hundred; read no further
#: (``--spec /dev/zero`` ends).
MAX_SPEC_BYTES = 1_000_000

#: Cells of one sweep: far beyond a month of a large cluster.
MAX_CELLS = 1_000_000

#: Cells a sweep runs without ``--yes``: 10,000 cells of a minute are a week on a 1-core
#: machine; a larger grid is more often a typo (seeds 1000000) than a plan.
MAX_CELLS_UNCONFIRMED = 10_000

#: How far (m) a random trocar placement may slide a constraint along its link: a metre is
#: longer than any instrument shaft or arm link.
MAX_TROCAR_SHIFT_M = 1.0

#: The largest excursion (m) of a random operator path from the scripted target: a metre is
#: beyond the reach of a surgical arm around its home pose.
MAX_PATH_AMPLITUDE_M = 1.0

#: The supervisor's levels: a constraint error (m) beyond a metre is no longer a drift of
#: the constraint, a port force beyond 1 kN would tear any tissue; a ramp of the operator's
#: scale longer than a minute leaves the operator without control for it.
MAX_SUPERVISOR_ERROR_M = 1.0
MAX_SUPERVISOR_FORCE_N = 1_000.0
MAX_SUPERVISOR_RAMP_S = 60.0

#: A network master's watchdog timeout (s): below 5 ms one late datagram of a 1 kHz master
#: releases it; beyond 5 s a master that died leaves the robot following its last command
#: for longer than anyone would wait.
MIN_INPUT_TIMEOUT_S = 0.005
MAX_INPUT_TIMEOUT_S = 5.0
