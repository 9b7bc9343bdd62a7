"""The operator's events, coalesced and applied on one thread, never on the control thread.

viser runs every GUI and gizmo callback on a pool of threads, as fast as messages come in:
a page (or a script) sending thousands of events a second would otherwise have each one
take the app's lock, and each rate change rebuild the controllers, until the control loop
starves (docs/design.md section 5.3). The UI therefore only **posts** events here:

* an event with a **key** (a slider, a gizmo, a menu) replaces the pending event with the
  same key: the latest value wins, at the place in the queue of the first one pending;
* a **throttled** event (one that rebuilds the controllers or reads a file: the rate, a
  controller, a scene) runs at most once per :data:`THROTTLE` seconds; the events behind
  it wait for it, so the order of what the operator did is kept;
* an event without a key (a button) is queued as it is, at most :data:`MAX_PENDING`
  pending in all: more are refused.

One worker thread applies them in order. An action that raises ``ValueError`` (or any
other error) is reported to ``on_error`` with the context it was posted with (the UI
notifies the browser that sent it); the worker goes on.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass

#: a throttled event runs at most once per this many seconds
THROTTLE = 0.1
#: events waiting at once; more are refused (a key already pending is always replaced)
MAX_PENDING = 256


@dataclass
class _Event:
    action: Callable[[], object]
    context: object
    throttled: bool


class Inbox:
    """Coalesces events and applies them on its own thread (:meth:`start`)."""

    def __init__(self, on_error: Callable[[object, Exception], None],
                 throttle: float = THROTTLE) -> None:
        self.on_error = on_error
        self.throttle = throttle
        self._pending: OrderedDict[object, _Event] = OrderedDict()
        self._ready = threading.Condition()
        self._busy = False
        self._last_throttled = -float("inf")
        self._unique = itertools.count()
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="inbox", daemon=True)
        self.applied = 0  # events run
        self.coalesced = 0  # events replaced by a later one with the same key
        self.refused = 0  # events refused because too many were pending

    def post(self, action: Callable[[], object], key: object = None, context: object = None,
             throttled: bool = False) -> bool:
        """Queue ``action`` (replacing a pending one with the same ``key``); False when
        refused (too many pending), after telling ``on_error``."""
        with self._ready:
            if key is not None and key in self._pending:
                self._pending[key] = _Event(action, context, throttled)
                self.coalesced += 1
                return True
            if len(self._pending) >= MAX_PENDING:
                self.refused += 1
                refused = True
            else:
                refused = False
                self._pending[("once", next(self._unique)) if key is None else key] = \
                    _Event(action, context, throttled)
                self._ready.notify_all()
        if refused:
            self.on_error(context, ValueError(f"too many actions at once ({MAX_PENDING} "
                                              "waiting): this one was dropped"))
        return not refused

    @property
    def thread(self) -> threading.Thread:
        """The thread this runs on."""
        return self._thread

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        with self._ready:
            self._stop = True
            self._ready.notify_all()
        self._thread.join(timeout)

    def drain(self, timeout: float) -> bool:
        """Wait until nothing is pending or running (bounded); whether it got there."""
        deadline = time.monotonic() + timeout
        with self._ready:
            while self._pending or self._busy:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._ready.wait(remaining)
        return True

    def _next(self) -> _Event | None:
        """The first pending event once it may run (None: stopping)."""
        with self._ready:
            while not self._stop:
                if not self._pending:
                    self._ready.wait()
                    continue
                key, event = next(iter(self._pending.items()))
                if event.throttled:
                    wait = self._last_throttled + self.throttle - time.monotonic()
                    if wait > 0:  # meanwhile a newer value may replace it
                        self._ready.wait(wait)
                        continue
                    self._last_throttled = time.monotonic()
                del self._pending[key]
                self._busy = True
                return event
            return None

    def _run(self) -> None:
        while (event := self._next()) is not None:
            try:
                event.action()
            except Exception as error:  # told to the operator; the inbox goes on
                self.on_error(event.context, error)
            finally:
                with self._ready:
                    self._busy = False
                    self.applied += 1
                    self._ready.notify_all()
