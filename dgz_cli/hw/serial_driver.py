"""What every serial-bus hand driver shares: its joint mapper, bus statistics and port closing."""

from __future__ import annotations

import numpy as np

from dgz_cli.hw.driver import HandDriver


class SerialHandDriver(HandDriver):
    """A :class:`HandDriver` talking over one serial port (``self.ser``) through a protocol bus
    (``self.bus`` with ``stats.errors``) and mapping channels with ``self.mapper``."""

    ser = None
    bus = None
    mapper = None

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.mapper.limits()

    @property
    def bus_errors(self) -> int:
        return self.bus.stats.errors if self.bus else 0

    def close(self) -> None:
        if self.ser is not None:
            try:
                self.ser.close()
            except OSError:
                pass
        self.ser = None
        self.connected = False
