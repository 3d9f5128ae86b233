"""Fixed-rate timing with absolute deadlines, and the two-stage Ctrl-C guard."""

from __future__ import annotations

import math
import signal
import threading
import time


class RateLoop:
    """Step k is due at t0 + k·period. ``wait()`` sleeps until the current deadline; a step that ends
    after its deadline is an overrun: the missed slots are skipped (the grid keeps its phase) and counted."""

    def __init__(self, rate_hz: float, clock=time.monotonic, sleep=time.sleep) -> None:
        if rate_hz <= 0:
            raise ValueError("rate must be positive")
        self.period = 1.0 / rate_hz
        self.clock, self.sleep = clock, sleep
        self.overruns = 0
        self.consecutive = 0
        self.periods: list[float] = []
        self.start()

    def start(self) -> None:
        self.t0 = self.clock()
        self.deadline = self.t0 + self.period
        self._last = self.t0

    def wait(self) -> float:
        """Block until the next tick; return this step's lateness in seconds (≤ 0: on time)."""
        now = self.clock()
        late = now - self.deadline
        if late > 0:
            self.overruns += 1
            self.consecutive += 1
            self.deadline += (math.floor(late / self.period) + 1) * self.period
        else:
            self.consecutive = 0
        remaining = self.deadline - self.clock()
        if remaining > 0:
            self.sleep(remaining)
        tick = self.clock()
        self.periods.append(tick - self._last)
        self._last = tick
        self.deadline += self.period
        return late


class InterruptGuard:
    """First Ctrl-C: ask the loop to stop at the next step boundary (then hold/relax as configured).
    Second Ctrl-C: raise KeyboardInterrupt at once (the runtime relaxes the hand immediately).
    Installs a SIGINT handler only in the main thread; elsewhere it is a plain flag."""

    def __init__(self) -> None:
        self.count = 0
        self._previous = None

    @property
    def stop_requested(self) -> bool:
        return self.count > 0

    def request_stop(self) -> None:
        self.count = max(self.count, 1)

    def _handler(self, signum, frame) -> None:
        self.count += 1
        if self.count >= 2:
            raise KeyboardInterrupt

    def __enter__(self) -> "InterruptGuard":
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handler)
        return self

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None
