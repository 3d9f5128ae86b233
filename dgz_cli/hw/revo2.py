"""BrainCo Revo2 over Modbus RTU (460800 baud, slave 126 left / 127 right).

Positions are normalized 0 (open) … 1000 (closed); radians use the limits read from the device:
rad = (min_deg + n·(max_deg − min_deg)/1000)·π/180. Register use (see docs/deploy.md):
FC03 901 SKU, 937 unit mode (0 = normalized, 1 = physical: positions in degrees), 946/952 min/max position
(°, 6 each);
FC16 1022 = 6 × [position, speed]; FC16 1046 = 6 PWM words (all 0 = motors unpowered);
FC04 2000 = 24 words read as 4 blocks of 6: position, speed, current (mA, signed), state;
FC04 3000 / 3010 = firmware version / serial number (ASCII, 10 registers each).

A hand left in physical-unit mode (937 = 1) is detected at connect (a read): its feedback positions are
degrees, converted to the normalized scale with the limits read from the device, so a dry run reads it
correctly and writes nothing. ``enable()`` — the first write of a real run — switches it to normalized mode
and reads 937 back before any position is written; no position is ever written in physical-unit mode.
"""

from __future__ import annotations

import time

import numpy as np

from dgz_cli.hw.driver import DeviceInfo, HandState
from dgz_cli.hw.errors import IdentityError
from dgz_cli.hw.jointmap import JointMapper
from dgz_cli.hw.modbus_hand import ModbusHand
from dgz_cli.hw.modbus_rtu import registers_to_ascii, to_signed

SKU, UNIT_MODE, MIN_POS, MAX_POS = 901, 937, 946, 952
POS_SPEED, PWM = 1022, 1046
FEEDBACK, FIRMWARE, SERIAL = 2000, 3000, 3010
MAX_LIMIT_DEG = 180  # a finger joint's range read from the device must lie inside ±180°
NORMALIZED, PHYSICAL = 0, 1  # register 937


class Revo2Driver(ModbusHand):
    protocol = "revo2_modbus"
    wiring_hint = ("check power and the RS485 A/B wiring; slave 126 is the left hand, 127 the right (slave_id in "
                   "the hand file); the baud rate is 460800")

    def connect(self) -> DeviceInfo:
        self._open()
        try:
            bus, s = self.bus, self.slave
            sku = self._identify("the SKU (register 901)", lambda: bus.read_holding(s, SKU, 1)[0])
            if self.settings.skus and sku not in self.settings.skus:
                raise IdentityError(f"{self.port}: device reports SKU {sku}, not one of {self.settings.skus}",
                                    "is this a Revo2? otherwise fix revo2.skus in the hand file")
            firmware = registers_to_ascii(self._identify("the firmware version",
                                                         lambda: bus.read_input(s, FIRMWARE, 10)))
            serial = registers_to_ascii(self._identify("the serial number", lambda: bus.read_input(s, SERIAL, 10)))
            lim = to_signed(self._identify("the position limits", lambda: bus.read_holding(s, MIN_POS, 12)))
            self.limits_deg = list(zip(lim[:6], lim[6:]))
            bad = [(c.name, lo, hi) for c, (lo, hi) in zip(self.cfg.channels, self.limits_deg)
                   if not (-MAX_LIMIT_DEG <= lo < hi <= MAX_LIMIT_DEG)]
            if bad:
                name, lo, hi = bad[0]
                raise IdentityError(f"{self.port}: Revo2 reports position limits [{lo}, {hi}]° for '{name}' "
                                    f"(registers {MIN_POS}/{MAX_POS}): not a finger's range (±{MAX_LIMIT_DEG}°)",
                                    "check the firmware's unit mode and calibration with BrainCo's tool")
            self.mapper = JointMapper(self.cfg, self.spec, self.limits_deg, where=f"{self.port}: Revo2")
            self.unit_mode = self._identify("the unit mode (937)", lambda: bus.read_holding(s, UNIT_MODE, 1)[0])
            if self.unit_mode not in (NORMALIZED, PHYSICAL):
                raise IdentityError(f"{self.port}: Revo2 reports unit mode {self.unit_mode} (register {UNIT_MODE}): "
                                    f"neither normalized ({NORMALIZED}) nor physical ({PHYSICAL})",
                                    "check the firmware with BrainCo's tool, or set register 937 to 0")
        except BaseException:
            self.close()
            raise
        self.connected = True
        self.info = DeviceInfo(self.port, self.protocol, {"slave": str(s), "SKU": str(sku),
                                                          "firmware": firmware or "(empty)",
                                                          "serial": serial or "(empty)",
                                                          "unit mode": str(self.unit_mode)})
        return self.info

    def enable(self) -> None:
        """Switch a hand left in physical-unit mode to normalized mode, then read the mode back: a hand that
        does not switch is refused before any position is written."""
        if self.unit_mode != NORMALIZED:
            self.bus.write_single(self.slave, UNIT_MODE, NORMALIZED)
            mode = self.bus.read_holding(self.slave, UNIT_MODE, 1)[0]
            if mode != NORMALIZED:
                raise IdentityError(f"{self.port}: Revo2 stays in unit mode {mode} after writing {NORMALIZED} to "
                                    f"register {UNIT_MODE}",
                                    "set normalized mode (937 = 0) with BrainCo's tool, then retry")
            self.unit_mode = NORMALIZED

    def _normalized(self, pos: list[int]) -> list[float]:
        """Feedback positions (device order) on the normalized 0–1000 scale, whatever the unit mode."""
        if self.unit_mode == NORMALIZED:
            return list(pos)
        deg = to_signed(pos)  # physical mode: degrees, on the scale of the limits 946/952
        return [1000.0 * (d - lo) / (hi - lo) for d, (lo, hi) in zip(deg, self.limits_deg)]

    def read_state(self) -> HandState:
        regs = self.bus.read_input(self.slave, FEEDBACK, 24)
        stamp = time.monotonic()
        raw = regs[0:6]
        pos = self._normalized(raw)
        current = to_signed(regs[12:18])
        return HandState(q=self._checked(self.mapper.to_rad(pos), raw), effort=self.mapper.reorder(current),
                         effort_kind="current_mA", stamp=stamp, fingerprint=bytes(str(regs), "ascii"),
                         native=list(raw))

    def _write_native(self, native: list[int], speed: int) -> None:
        if self.unit_mode != NORMALIZED:  # the set-points would be read as degrees
            raise IdentityError(f"{self.port}: refusing to write positions: Revo2 is in physical unit mode "
                                f"(register {UNIT_MODE} = {self.unit_mode})",
                                "enable() switches it to normalized mode; set 937 to 0 if that failed")
        words = []
        for n in native:
            words += [int(n), int(speed)]
        self.bus.write_multiple(self.slave, POS_SPEED, words)

    def write_targets(self, q: np.ndarray) -> None:
        self._write_native(self._native_targets(q), self.settings.speed)

    def relax(self) -> None:
        """Open slowly (Revo2 fingers are not backdrivable: opening is how it lets go)."""
        self._write_native(self._native_targets(self.open_pose()), self.settings.relax_speed)

    def torque_off(self) -> None:
        """Zero PWM on every finger: the motors are unpowered and the fingers stay where they are."""
        self.bus.write_multiple(self.slave, PWM, [0] * 6)
