"""A low-pass filter on the sensed wrench (docs/design.md section 21.3).

``order`` identical first-order sections in cascade, each the exact discretisation of
``tau y' = x - y`` (``tau = 1 / (2 pi f_c)``) at the control period ``dt``:

    y_n = y_{n-1} + alpha (x_n - y_{n-1}),     alpha = 1 - beta,   beta = exp(-2 pi f_c dt),

so one section is ``H(z) = alpha z / (z - beta)`` and the filter ``H(z)^order``. Its lag
enters the force loop's stability bound (:func:`teleop.loop.force_stability.force_loop_bound`
takes ``beta`` and ``order``). The sections start at the first reading (no step from zero).
"""

from __future__ import annotations

import math

import numpy as np

from constraints.validation import as_number


class WrenchLowPass:
    """``order`` (1 or 2) first-order sections of cut-off ``cutoff`` (Hz, below the Nyquist
    frequency ``1 / (2 dt)``) at period ``dt`` (s) on a 6-D wrench."""

    def __init__(self, cutoff: float, dt: float, order: int = 2) -> None:
        self.dt = as_number(dt, "dt", positive=True)
        nyquist = 0.5 / self.dt
        self.cutoff = as_number(cutoff, "filter cutoff", positive=True)
        if self.cutoff >= nyquist:
            raise ValueError(f"filter cutoff {self.cutoff:g} Hz must be below the Nyquist "
                             f"frequency {nyquist:g} Hz of dt = {self.dt:g} s")
        if order not in (1, 2) or isinstance(order, bool):
            raise ValueError(f"filter order must be 1 or 2, got {order!r}")
        self.order = order
        #: ``beta = exp(-2 pi f_c dt)``: each section's pole.
        self.pole = math.exp(-2.0 * math.pi * self.cutoff * self.dt)
        self._sections: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the readings: the next one starts the sections."""
        self._sections = None

    def __call__(self, wrench: np.ndarray) -> np.ndarray:
        """The filtered wrench after the reading ``wrench`` (6,); ``ValueError`` when it is
        not finite (the state is left as it was)."""
        reading = np.asarray(wrench, dtype=float)
        if reading.shape != (6,) or not np.all(np.isfinite(reading)):
            raise ValueError("the force/torque sensor's wrench is not finite")
        if self._sections is None:
            self._sections = np.tile(reading, (self.order, 1))
            return reading.copy()
        alpha = 1.0 - self.pole
        section_input = reading
        for section in self._sections:
            section += alpha * (section_input - section)
            section_input = section
        return self._sections[-1].copy()
