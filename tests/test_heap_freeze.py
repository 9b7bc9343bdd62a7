"""The heap's freeze shared by the plants that hold it (teleop/heap_freeze.py)."""

from __future__ import annotations

import gc

from teleop.heap_freeze import freeze_heap, release_heap


class Holder:
    """A plant's stand-in: the freeze is kept by identity."""


def test_the_heap_is_unfrozen_when_the_last_holder_lets_go():
    first, second = Holder(), Holder()
    freeze_heap(first)
    freeze_heap(second)
    try:
        assert gc.get_freeze_count() > 0
        release_heap(first)
        assert gc.get_freeze_count() > 0  # the second still drives its robot
        release_heap(first)  # twice: nothing more
        assert gc.get_freeze_count() > 0
        release_heap(second)
        assert gc.get_freeze_count() == 0
    finally:
        release_heap(first)
        release_heap(second)


def test_a_holder_that_never_froze_leaves_the_heap_alone():
    gc.freeze()  # a freeze of someone else's (the application's own)
    try:
        release_heap(Holder())
        assert gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()
