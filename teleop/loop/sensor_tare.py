"""The force/torque sensor's tare (docs/design.md section 21.2): the mean reading over a
window out of contact is the sensor's offset (its bias and the tool's weight), subtracted
from every later reading. A law regulates the reading, so an offset left in it is a force
error no gain removes (21.4)."""

from __future__ import annotations

import numpy as np


class SensorTare:
    """Averages the first ``samples`` readings (the tool out of contact), then returns each
    reading minus that mean; before the window is full, the reading with the mean so far
    removed (zero when nothing was read)."""

    def __init__(self, samples: int) -> None:
        if not isinstance(samples, int) or isinstance(samples, bool) or samples < 1:
            raise ValueError(f"tare samples must be an integer >= 1, got {samples!r}")
        self.samples = samples
        self.count = 0
        self.offset = np.zeros(6)

    @property
    def done(self) -> bool:
        """The window is full: the offset is fixed."""
        return self.count >= self.samples

    def __call__(self, wrench: np.ndarray) -> np.ndarray:
        """``wrench`` (6,) without the offset; ``ValueError`` when it is not finite."""
        reading = np.asarray(wrench, dtype=float)
        if reading.shape != (6,) or not np.all(np.isfinite(reading)):
            raise ValueError(f"a wrench to tare must be 6 finite numbers, got {wrench!r}")
        if not self.done:
            self.count += 1
            self.offset += (reading - self.offset) / self.count
        return reading - self.offset
