"""Fake Inspire RH56 on a pty (Modbus RTU slave, FC03/06/16 on one register bank).

ANGLE_SET 1486 (0xFFFF = −1 = no change), FORCE_SET 1498, SPEED_SET 1522, actuator position 1534,
ANGLE_ACT 1546, FORCE_ACT 1582 (signed), current 1594, error/status/temperature 1606/1612/1618, ID 1000."""

from __future__ import annotations

from dgz_cli.hw.fakes.base import approach
from dgz_cli.hw.fakes.modbus import ModbusFake, u16


class InspireFake(ModbusFake):
    name = "inspire"

    def __init__(self, slave: int = 1, rate: float = 4000.0, **kw) -> None:
        super().__init__(slave, **kw)
        self.rate = rate  # angle units per second at SPEED_SET 1000
        self.angle = [1000.0] * 6  # open
        self.goal = [1000.0] * 6
        self._tick = 0
        h = self.holding
        for reg in (1000, 1004, 1005, 1009):
            h[reg] = 0
        h[1000] = slave
        for base, value in ((1486, 1000), (1498, 500), (1522, 1000), (1534, 0), (1540, 0), (1546, 1000),
                            (1582, 0), (1594, 0), (1606, 0), (1612, 0), (1618, 30)):
            for i in range(6):
                h[base + i] = value
        self.refresh()

    def on_write(self, addr: int, values: list[int]) -> None:
        if addr < 1492 and addr + len(values) > 1486:
            for i in range(6):
                v = self.holding[1486 + i]
                if v != 0xFFFF:  # −1: keep this finger's set-point
                    self.goal[i] = float(min(1000, v))

    def advance(self, dt: float) -> None:
        for i in range(6):
            speed = self.holding[1522 + i] / 1000.0
            self.angle[i] = approach(self.angle[i], self.goal[i], self.rate * speed * max(dt, 0.0))

    def refresh(self) -> None:
        if self.fault == "stale":
            return
        self._tick += 1
        h = self.holding
        for i in range(6):
            err = abs(self.goal[i] - self.angle[i])
            h[1534 + i] = u16(round(2000 - 2 * self.angle[i]))
            h[1546 + i] = u16(self.corrupt_position if self.corrupted(i) else round(self.angle[i]))
            h[1582 + i] = u16(-3 + (self.requests % 3) if err >= 1 else (self.requests % 3))
            h[1594 + i] = u16(50 + min(300, int(err)))
            h[1612 + i] = 1 if err >= 1 else 0
