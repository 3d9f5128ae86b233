"""A fake device on a pseudo-terminal: a thread reads the master end, the driver opens ``self.port``.

Fault switches (set ``fake.fault`` at any time, ``None`` clears):
``no_answer`` (requests are read and dropped), ``crc`` (replies go out with a corrupted checksum),
``exception`` (every request is refused: Modbus exception 4 / Dynamixel hardware-alert status),
``stale`` (feedback frozen at the value it had when the switch was set), ``disconnect`` (the pty is
closed: the driver's next read or write fails like an unplugged USB adapter).

Corrupt readings: set ``fake.corrupt_position`` to a raw register value (e.g. 0x7FFFFFFF on Dynamixel,
65535 on the Modbus hands) and every position reading returns it, on every channel or only on the
channel indices (device order) in ``fake.corrupt_channels``. ``None`` clears it.
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty

FAULTS = (None, "no_answer", "crc", "exception", "stale", "disconnect")


class PtyFake:
    name = "fake"

    def __init__(self, clock=time.monotonic) -> None:
        self.master_fd, self.slave_fd = os.openpty()
        tty.setraw(self.slave_fd)
        self.port = os.ttyname(self.slave_fd)
        self.clock = clock
        self.lock = threading.RLock()
        self._fault: str | None = None
        self._stop = threading.Event()
        self._buf = bytearray()
        self._thread = threading.Thread(target=self._run, name=f"{self.name}-fake", daemon=True)
        self.requests = 0
        self.closed = False
        self.corrupt_position: int | None = None
        self.corrupt_channels: set[int] | None = None
        self._last = clock()

    # -- lifecycle ---------------------------------------------------------------------------------
    def start(self) -> "PtyFake":
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=1.0)
        self._close_fds()

    def __enter__(self) -> "PtyFake":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _close_fds(self) -> None:
        with self.lock:
            if not self.closed:
                self.closed = True
                for fd in (self.master_fd, self.slave_fd):
                    try:
                        os.close(fd)
                    except OSError:
                        pass

    # -- faults ------------------------------------------------------------------------------------
    @property
    def fault(self) -> str | None:
        return self._fault

    @fault.setter
    def fault(self, value: str | None) -> None:
        if value not in FAULTS:
            raise ValueError(f"unknown fault {value!r}; one of {FAULTS}")
        with self.lock:
            if value == "stale":
                self.freeze()
            self._fault = value
            if value == "disconnect":
                self._close_fds()

    def corrupted(self, channel: int) -> bool:
        """True if position readings of ``channel`` (device order) are to be replaced by ``corrupt_position``."""
        return self.corrupt_position is not None and (self.corrupt_channels is None or channel in self.corrupt_channels)

    def freeze(self) -> None:
        """Subclasses snapshot their feedback here."""

    # -- I/O loop ----------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set() and not self.closed:
            try:
                ready, _, _ = select.select([self.master_fd], [], [], 0.005)
            except (OSError, ValueError):
                return
            if not ready:
                with self.lock:
                    self._step_physics()
                continue
            try:
                chunk = os.read(self.master_fd, 4096)
            except OSError:
                if self.closed:
                    return
                time.sleep(0.001)  # EIO while no client holds the slave end
                continue
            with self.lock:
                self._buf += chunk
                while True:
                    frame = self.take_frame(self._buf)
                    if frame is None:
                        break
                    self.requests += 1
                    self._step_physics()
                    if self._fault in ("no_answer", "disconnect"):
                        continue
                    reply = self.handle(frame)
                    if reply:
                        if self._fault == "crc":
                            reply = reply[:-1] + bytes([reply[-1] ^ 0x5A])
                        self._send(reply)

    def _step_physics(self) -> None:
        now = self.clock()
        self.advance(now - self._last)
        self._last = now

    def _send(self, data: bytes) -> None:
        try:
            os.write(self.master_fd, data)
        except OSError:
            pass

    # -- protocol hooks ----------------------------------------------------------------------------
    def take_frame(self, buf: bytearray) -> bytes | None:
        """Remove and return one complete request from ``buf`` (dropping garbage), or None."""
        raise NotImplementedError

    def handle(self, frame: bytes) -> bytes | None:
        raise NotImplementedError

    def advance(self, dt: float) -> None:
        """Move the simulated actuators by ``dt`` seconds."""


def approach(current: float, goal: float, step: float) -> float:
    if abs(goal - current) <= step:
        return goal
    return current + step if goal > current else current - step
