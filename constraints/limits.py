"""The largest numbers a constraint, an obstacle or a collision setting accepts.

The constraints and obstacles are what session and scene files carry, so these bounds are
checked where they are built (the Python API, the files and the UI alike). They are the
constraint layer's part of the one table of limits, :mod:`teleop.limits`, which lists them
with the rest (docs/sessions.md, "Limits"). Each bound is far beyond any real use; the
line above it says why.
"""

from __future__ import annotations

#: A world or link coordinate (m): a hole's centre, a plane's points, a lock's target, an
#: obstacle's centre. A hundred metres is beyond any robot cell, and every distance
#: squared stays far from a float's overflow.
MAX_POSITION_M = 100.0

#: An obstacle's radius, length or box edge (m): a wall of a hundred metres is a wall.
MAX_OBSTACLE_SIZE_M = 100.0

#: The velocity (m/s) of moving geometry (per axis) and a collision damper's approach
#: speed: ten times the fastest a surgical or UR5 tool moves.
MAX_SPEED_M_S = 10.0

#: A constraint's drift gain K (1/s): a hole is stable for K dt < 2, so above this it is
#: unstable at every control rate up to teleop.limits.MAX_RATE_HZ (10 kHz).
MAX_CONSTRAINT_GAIN = 20_000.0

#: The stiffest abdominal wall around a port (N/m): 100 N/mm, a hundred times the
#: default; at 1e10 N/m the physics plant is unstable.
MAX_TISSUE_STIFFNESS = 1e5

#: The most viscous abdominal wall (N s/m): a hundred times the default.
MAX_TISSUE_DAMPING = 1e3

#: The collision damper's safety and detection distances (m): a metre, beyond any
#: clearance kept around an arm.
MAX_COLLISION_DISTANCE_M = 1.0

#: The robot's response time a collision damper counts on (s): a minute, beyond any servo
#: (a 20 Hz servo's is 8 ms); a longer one only slows the damper further.
MAX_RESPONSE_TIME_S = 60.0

#: Obstacles in one collision avoidance. A step's cost hardly grows with them (the
#: broadphase: 0.08 ms of Python rows at 100 on sda10f, 0.17 ms at 1,200); the compiled
#: step's workspace does, with the square of the pairs (52 MB at 100, 748 MB at 400,
#: 6.6 GB at 1,200: docs/design.md 18.3).
MAX_OBSTACLES = 100
