"""The process's heap kept out of the cyclic collector while a robot on the wire is driven
(docs/ros2.md, "Real-time threads").

``gc.freeze`` is the process's: two plants open at once share it, and the heap is given
back to the collector (``gc.unfreeze``) only when the last of them lets go.
"""

from __future__ import annotations

import gc
import threading

_holders: set[int] = set()
_lock = threading.Lock()


def freeze_heap(holder: object) -> None:
    """The objects alive collected, then frozen, on behalf of ``holder``."""
    with _lock:
        gc.collect()
        gc.freeze()
        _holders.add(id(holder))


def release_heap(holder: object) -> None:
    """``holder``'s freeze let go; the heap unfrozen when no other holder keeps it."""
    with _lock:
        if id(holder) not in _holders:
            return
        _holders.discard(id(holder))
        if not _holders:
            gc.unfreeze()
