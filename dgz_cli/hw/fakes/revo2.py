"""Fake BrainCo Revo2 on a pty (Modbus RTU slave): SKU 901, limits 946/952, set-points 1022, PWM 1046,
feedback FC04 2000 (6 positions, 6 speeds, 6 currents, 6 states), firmware FC04 3000, serial FC04 3010.

Unit mode 937: 0 normalized (positions 0–1000), 1 physical (positions in degrees between the limits
946/952, as a hand left in that mode by BrainCo's tool reports them); ``unit_mode=1`` starts in it. The
mode is applied at every feedback refresh and to every set-point write (1010/1022). ``start``: the initial
finger positions (normalized)."""

from __future__ import annotations

from dgz_cli.hw.fakes.base import approach
from dgz_cli.hw.fakes.modbus import ModbusFake, ascii_regs, u16

SKU = 0x0202
MIN_DEG = [0, 0, 0, 0, 0, 0]
MAX_DEG = [59, 90, 81, 81, 81, 81]  # thumb, thumb_aux, index, middle, ring, little


class Revo2Fake(ModbusFake):
    name = "revo2"

    def __init__(self, slave: int = 127, rate: float = 4000.0, firmware: str = "2.0.5", serial: str = "FAKE-R2-0001",
                 min_deg: list[int] | None = None, max_deg: list[int] | None = None, unit_mode: int = 0,
                 start: list[float] | None = None, **kw) -> None:
        super().__init__(slave, **kw)
        self.min_deg, self.max_deg = list(min_deg or MIN_DEG), list(max_deg or MAX_DEG)
        self.rate = rate  # normalized units per second
        self.pos = [float(v) for v in (start or [0.0] * 6)]  # normalized, whatever the unit mode
        self.goal = list(self.pos)
        self.pwm_off = False
        self._tick = 0
        h = self.holding
        h[901] = SKU
        for i in range(6):
            h[930 + i] = 1500
            h[946 + i] = u16((min_deg or MIN_DEG)[i])
            h[952 + i] = u16((max_deg or MAX_DEG)[i])
            h[958 + i] = 300
            h[964 + i] = 1500
        h[937] = unit_mode
        for base in (1010, 1022):
            for i in range(12):
                h[base + i] = 0
        for base in (1034, 1040, 1046, 1070):
            for i in range(6):
                h[base + i] = 0
        for i, v in enumerate(ascii_regs(firmware, 10)):
            self.input[3000 + i] = v
        for i, v in enumerate(ascii_regs(serial, 10)):
            self.input[3010 + i] = v
        self.refresh()

    def on_write(self, addr: int, values: list[int]) -> None:
        h = self.holding
        if 1010 <= addr < 1034:
            base = 1010 if addr < 1022 else 1022
            self.pwm_off = False
            for i in range(6):
                self.goal[i] = self.from_units(i, h[base + 2 * i])
        elif 1046 <= addr < 1052 and all(h[1046 + i] == 0 for i in range(6)):
            self.pwm_off = True  # zero PWM on every finger: motors unpowered
            self.goal = list(self.pos)

    @property
    def physical(self) -> bool:
        return self.holding[937] == 1

    def from_units(self, i: int, word: int) -> float:
        """A set-point word (current unit mode) → normalized 0–1000."""
        if not self.physical:
            return float(min(1000, word))
        deg = word - 0x10000 if word & 0x8000 else word
        lo, hi = self.min_deg[i], self.max_deg[i]
        return float(min(1000.0, max(0.0, 1000.0 * (deg - lo) / (hi - lo))))

    def to_units(self, i: int, n: float) -> int:
        """A normalized position → the feedback word in the current unit mode."""
        if not self.physical:
            return round(n)
        lo, hi = self.min_deg[i], self.max_deg[i]
        return round(lo + n * (hi - lo) / 1000.0)

    def advance(self, dt: float) -> None:
        if self.pwm_off:
            return
        step = self.rate * max(dt, 0.0)
        self.pos = [approach(p, g, step) for p, g in zip(self.pos, self.goal)]

    def refresh(self) -> None:
        if self.fault == "stale":
            return
        self._tick += 1
        jitter = self.requests % 3  # sensor noise: a live device never repeats a frame exactly
        for i in range(6):
            err = abs(self.goal[i] - self.pos[i])
            self.input[2000 + i] = u16(self.corrupt_position if self.corrupted(i) else self.to_units(i, self.pos[i]))
            self.input[2006 + i] = u16(0 if err < 1 else round(self.rate / 10))
            self.input[2012 + i] = u16(0 if self.pwm_off else 80 + min(400, int(err)) + jitter)
            self.input[2018 + i] = 0 if err < 1 else 1
