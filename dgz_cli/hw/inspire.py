"""Inspire RH56 (DFX) over Modbus RTU (115200 8N1, node id 1): one register per finger.

Angles 0–1000 with 1000 = open; radians use the spec joint limits: rad = lower + (1000 − n)/1000·(upper −
lower), so closing (n → 0) is +q = +FLEX on every finger (checked by tests). Registers: 1000 ID,
1486 ANGLE_SET, 1498 FORCE_SET, 1522 SPEED_SET, 1546 ANGLE_ACT, 1582 FORCE_ACT (signed), 1606 error.
"""

from __future__ import annotations

import time

import numpy as np

from dgz_cli.hw.driver import DeviceInfo, HandState
from dgz_cli.hw.errors import IdentityError, ImplausibleReading
from dgz_cli.hw.jointmap import JointMapper
from dgz_cli.hw.modbus_hand import ModbusHand
from dgz_cli.hw.modbus_rtu import to_signed

ID, ANGLE_SET, FORCE_SET, SPEED_SET = 1000, 1486, 1498, 1522
ANGLE_ACT, FORCE_ACT, ERROR = 1546, 1582, 1606


class InspireDriver(ModbusHand):
    protocol = "inspire_modbus"
    wiring_hint = "check the 24 V supply, the RS485 A/B wiring, node id (register 1000) and 115200 baud"

    def connect(self) -> DeviceInfo:
        self._open()
        try:
            bus, s = self.bus, self.slave
            dev_id = self._identify("its id (register 1000)", lambda: bus.read_holding(s, ID, 1)[0])
            if dev_id != s:
                raise IdentityError(f"{self.port}: Inspire answered as slave {s} but reports id {dev_id}",
                                    "set slave_id in the hand file to the hand's id")
            errors = self._identify("its error registers (1606)", lambda: bus.read_holding(s, ERROR, 6))
            self.mapper = JointMapper(self.cfg, self.spec, where=f"{self.port}: Inspire")
        except BaseException:
            self.close()
            raise
        self.connected = True
        self.info = DeviceInfo(self.port, self.protocol, {"id": str(dev_id),
                                                          "errors": ",".join(str(e) for e in errors)})
        return self.info

    def enable(self) -> None:
        self.bus.write_multiple(self.slave, FORCE_SET, [self.settings.force] * 6)
        self.bus.write_multiple(self.slave, SPEED_SET, [self.settings.speed] * 6)

    def read_state(self) -> HandState:
        angles = self.bus.read_holding(self.slave, ANGLE_ACT, 6)
        force = to_signed(self.bus.read_holding(self.slave, FORCE_ACT, 6))
        stamp = time.monotonic()
        return HandState(q=self._checked(self.mapper.to_rad(angles), angles), effort=self.mapper.reorder(force), effort_kind="force",
                         stamp=stamp, fingerprint=bytes(str(angles + force), "ascii"), native=list(angles))

    def write_targets(self, q: np.ndarray) -> None:
        native = self._native_targets(q)
        self.bus.write_multiple(self.slave, ANGLE_SET, native)
        self._last_set = native

    def hold(self) -> None:
        """ANGLE_SET := measured (checked for plausibility, clipped into the joint limits)."""
        self.write_targets(self.read_state().q)

    def relax(self) -> None:
        """Open slowly (the linear actuators are self-locking: opening is how the hand lets go)."""
        native = self._native_targets(self.open_pose())
        self.bus.write_multiple(self.slave, SPEED_SET, [self.settings.relax_speed] * 6)
        self.bus.write_multiple(self.slave, ANGLE_SET, native)
        self._last_set = native

    def torque_off(self) -> None:
        """No torque-enable register: stop every finger where it is (self-locking actuators hold).

        When the position cannot be trusted, the last set-point dgz wrote is repeated (nothing is written
        if dgz never commanded this hand: it is not being moved by dgz then)."""
        try:
            self.hold()
        except ImplausibleReading:
            last = getattr(self, "_last_set", None)
            if last is not None:
                self.bus.write_multiple(self.slave, ANGLE_SET, last)
