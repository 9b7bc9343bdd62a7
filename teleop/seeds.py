"""Independent random streams from one seed (docs/design.md 15.1).

A run's seed feeds several draws (the encoder noise, the calibration error, the trocar
placements, the operator paths); each takes its own child of the seed's
``SeedSequence`` (``spawn_key=(stream,)``), so no two streams overlap, for one seed or
across seeds. (``default_rng([seed, stream])`` would not do: NumPy reads a seed beyond
32 bits as two words, so ``[s, c]`` is the same stream as the seed ``s + c 2^32``.)
The encoder noise keeps the seed's own stream, ``default_rng(seed)``.
"""

from __future__ import annotations

import numpy as np


def stream(seed: int, number: int) -> np.random.Generator:
    """The generator of stream ``number`` (> 0) of ``seed``."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(number),)))
