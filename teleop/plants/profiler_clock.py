"""MuJoCo's profiler clock off while plants step (docs/design.md section 17.5).

MuJoCo times each stage of a physics step for ``MjData.timer`` when its timer callback,
``mjcb_time``, is set, and the ``mujoco`` Python package sets it to a clock of its own on
import: 32 readings of the clock per physics step, about 1.5 us of the plant's 10 us
period on sda10f (two steps), for a profile the plants never read. The callback reads no
state and writes only ``MjData.timer``, so every joint, velocity and force is the same bit
for bit without it (tests/test_profiler_clock.py). A timer the user installed
(``mujoco.set_mjcb_time``) is theirs and stays; ``mujoco.set_mjcb_time(None)`` brings the
package's clock back until the next plant is made.
"""

from __future__ import annotations

import ctypes
import functools
import sys
from pathlib import Path

import mujoco


@functools.cache
def _mujoco_library() -> ctypes.CDLL | None:
    """The ``mujoco`` package's ``libmujoco``, the one its bindings use (Linux); None
    where it is not found or not loadable."""
    if not sys.platform.startswith("linux"):
        return None
    libraries = sorted(Path(mujoco.__file__).resolve().parent.glob("libmujoco.so*"))
    if not libraries:
        return None
    try:
        return ctypes.CDLL(str(libraries[0]))
    except OSError:
        return None


def stop_profiler_clock() -> bool:
    """Clear ``mjcb_time`` where it is the ``mujoco`` package's own clock (no timer set
    from Python: ``mujoco.get_mjcb_time()`` is None); whether MuJoCo now steps without a
    clock."""
    library = _mujoco_library()
    if library is None or mujoco.get_mjcb_time() is not None:
        return False
    ctypes.c_void_p.in_dll(library, "mjcb_time").value = None
    return True
