"""How smooth a run was (docs/design.md section 17.3): the commanded joint jerk and the
share of the EE velocity's power at high frequency. Both are computed for every plant, so
the kinematic and the physics plant can be compared."""

from __future__ import annotations

import numpy as np

#: Above this frequency (Hz) an EE velocity's power counts as shaking, not motion: an
#: operator's hand moves below it.
HIGH_FREQUENCY_HZ = 3.0


def joint_jerk_rms(commands: np.ndarray, dt: float) -> float:
    """The jerkiest joint's RMS jerk of the command (rad/s^3; m/s^3 on a prismatic or
    base joint): with ``j_k = (qd_k - 2 qd_{k-1} + qd_{k-2}) / dt^2`` for ``k >= 2``, the
    largest over joints of ``sqrt(mean_k j_k^2)``; 0 with fewer than three commands."""
    commands = np.asarray(commands, dtype=float)
    if commands.ndim != 2 or len(commands) < 3:
        return 0.0
    jerk = (commands[2:] - 2.0 * commands[1:-1] + commands[:-2]) / dt ** 2
    return float(np.max(np.sqrt(np.mean(np.square(jerk), axis=0)), initial=0.0))


def power_fraction_above(velocity: np.ndarray, dt: float,
                         cutoff: float = HIGH_FREQUENCY_HZ) -> float:
    """The fraction of a vector signal's power above ``cutoff`` Hz: each component
    ``(steps, 3)`` detrended (its least-squares line removed), its one-sided FFT power
    ``|X_f|^2`` summed over components, then ``sum_{f > cutoff} P_f / sum_f P_f``; 0 for a
    signal with no power left after detrending (or fewer than three samples)."""
    velocity = np.asarray(velocity, dtype=float)
    velocity = velocity.reshape(len(velocity), -1)
    steps = len(velocity)
    if steps < 3:
        return 0.0
    t = np.arange(steps) * dt
    design = np.column_stack([np.ones(steps), t])
    trend, *_ = np.linalg.lstsq(design, velocity, rcond=None)
    power = np.sum(np.abs(np.fft.rfft(velocity - design @ trend, axis=0)) ** 2, axis=1)
    total = float(np.sum(power))
    if total <= 0.0:
        return 0.0
    frequencies = np.fft.rfftfreq(steps, dt)
    return min(1.0, float(np.sum(power[frequencies > cutoff]) / total))  # round-off above 1
