"""Fixed-rate timing with absolute deadlines, and the two-stage stop guard (Ctrl-C, SIGTERM, SIGHUP)."""

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


#: Signals that ask for a clean stop: Ctrl-C, ``kill``/systemd/``docker stop``/``timeout`` (SIGTERM), a closed
#: terminal or ssh session (SIGHUP). Each is handled like Ctrl-C.
STOP_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


def signal_name(signum: int | None) -> str:
    """``Ctrl-C`` for SIGINT, else the signal's name (``SIGTERM``, ``SIGHUP``)."""
    if signum is None or signum == signal.SIGINT:
        return "Ctrl-C"
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def exit_code_for(signum: int | None) -> int:
    """130 for Ctrl-C (SIGINT); 143 (128 + SIGTERM) for SIGTERM and SIGHUP, both termination requests."""
    return 130 if signum is None or signum == signal.SIGINT else 143


class InterruptGuard:
    """First Ctrl-C, SIGTERM or SIGHUP: ask the loop to stop at the next step boundary (then hold/relax as
    configured). A second one (any of them): raise KeyboardInterrupt at once (the runtime relaxes the hand
    immediately). Installs the handlers only in the main thread; elsewhere it is a plain flag.
    ``signum`` is the first signal received (None: none yet, or a stop requested in code). ``on_first`` is
    called from the first signal's handler (e.g. to set a training loop's stop request)."""

    def __init__(self, signals=STOP_SIGNALS, on_first=None) -> None:
        self.on_first = on_first
        self.count = 0
        self.signum: int | None = None
        self.last: int | None = None
        self.signals = tuple(signals)
        self._previous: dict = {}

    @property
    def stop_requested(self) -> bool:
        return self.count > 0

    @property
    def exit_code(self) -> int:
        return exit_code_for(self.signum)

    @property
    def what(self) -> str:
        return signal_name(self.signum)

    def request_stop(self) -> None:
        self.count = max(self.count, 1)

    @property
    def second(self) -> str:
        """What the second stop was: ``second Ctrl-C``, ``second SIGTERM``, ``SIGHUP after SIGTERM``."""
        first, last = signal_name(self.signum), signal_name(self.last)
        return f"second {first}" if first == last else f"{last} after {first}"

    def _handler(self, signum, frame) -> None:
        if self.count == 0:
            self.signum = signum
        self.last = signum
        self.count += 1
        if self.count >= 2:
            raise KeyboardInterrupt
        if self.on_first is not None:
            self.on_first()

    def __enter__(self) -> "InterruptGuard":
        if threading.current_thread() is threading.main_thread():
            for sig in self.signals:
                self._previous[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc) -> None:
        for sig, previous in self._previous.items():
            signal.signal(sig, previous if previous is not None else signal.SIG_DFL)
        self._previous = {}
