"""LEAP hand: 16 Dynamixel XC330 on Protocol 2.0 (4 Mbps) in current-based position mode.

Connect pings every ID (the error lists the silent ones) and probes fast-sync-read once, keeping
sync-read when it goes unanswered. ``enable()`` switches torque off, writes operating mode 5, P/I/D
gains and the goal current, sets goal := present (clipped into the joint limits; an implausible reading stops
before any write) and switches torque on. Radians: rad_sim = ticks·2π/4096 − π.
"""

from __future__ import annotations

import struct
import time

import numpy as np

from dgz_cli.hw.config import HandConfig
from dgz_cli.hw.driver import DeviceInfo, HandState
from dgz_cli.hw.dynamixel import DynamixelBus
from dgz_cli.hw.errors import TRANSIENT, HardwareError, IdentityError
from dgz_cli.hw.jointmap import JointMapper
from dgz_cli.hw.serial_driver import SerialHandDriver
from dgz_cli.hw.serial_port import open_serial
from dgz_cli.spec.models import HandSpec

OPERATING_MODE, TORQUE_ENABLE, D_GAIN, I_GAIN, P_GAIN = 11, 64, 80, 82, 84
GOAL_CURRENT, GOAL_POSITION, PRESENT = 102, 116, 126  # present current(2) velocity(4) position(4)


class LeapDriver(SerialHandDriver):
    protocol = "dynamixel2"

    def __init__(self, cfg: HandConfig, spec: HandSpec, port: str) -> None:
        super().__init__(spec, port)
        self.cfg = cfg
        self.settings = cfg.settings()
        self.ids = [int(c.id) for c in cfg.channels]
        self.mapper = JointMapper(cfg, spec, where=f"hand file '{cfg.name}'")
        self.ser = None
        self.bus: DynamixelBus | None = None
        self.fast = False

    def connect(self) -> DeviceInfo:
        p = self.cfg.port
        self.ser = open_serial(self.port, p.baudrate, p.timeout, p.bytesize, p.parity, p.stopbits)
        self.bus = DynamixelBus(self.ser, self.port, p.baudrate)
        try:
            models, missing = {}, []
            for dxl_id in self.ids:
                try:
                    models[dxl_id] = self.bus.ping(dxl_id)
                except TRANSIENT:
                    missing.append(dxl_id)
            if missing:
                raise IdentityError(f"{self.port}: no reply from Dynamixel ID(s) {missing} of {len(self.ids)} "
                                    f"at {p.baudrate} baud",
                                    "check the 5 V supply and the daisy chain to those motors; a wrong port or "
                                    "baud rate silences all of them (Dynamixel Wizard scans both)")
            accepted = self.settings.model_numbers
            wrong = {i: m for i, (m, _) in models.items() if accepted and m not in accepted}
            if wrong:
                raise IdentityError(f"{self.port}: unexpected Dynamixel model numbers {wrong}",
                                    f"the hand file accepts {accepted}; is this a LEAP hand?")
            self.fast = False
            if self.settings.fast_sync_read:
                try:
                    self.bus.fast_sync_read(PRESENT, 10, self.ids)
                    self.fast = True
                except (*TRANSIENT, IndexError):
                    self.fast = False  # older firmware: keep sync-read
        except BaseException:
            self.close()
            raise
        self.connected = True
        fw = sorted({f for _, f in models.values()})
        self.info = DeviceInfo(self.port, self.protocol, {
            "motors": str(len(models)), "models": ",".join(str(m) for m in sorted({m for m, _ in models.values()})),
            "firmware": ",".join(str(f) for f in fw), "read": "fast-sync-read" if self.fast else "sync-read"})
        return self.info

    def _sync_write(self, address: int, fmt: str, values) -> None:
        size = struct.calcsize(fmt)
        self.bus.sync_write(address, size, {i: struct.pack(fmt, int(v)) for i, v in zip(self.ids, values)})

    def enable(self) -> None:
        s = self.settings
        n = len(self.ids)
        goal = self._native_targets(self.read_state().q)  # checked reading, clipped goal: before any write
        self._sync_write(TORQUE_ENABLE, "<B", [0] * n)
        self._sync_write(OPERATING_MODE, "<B", [s.operating_mode] * n)
        self._sync_write(P_GAIN, "<H", [s.p_gain] * n)
        self._sync_write(I_GAIN, "<H", [s.i_gain] * n)
        self._sync_write(D_GAIN, "<H", [s.d_gain] * n)
        self._sync_write(GOAL_CURRENT, "<H", [s.goal_current] * n)
        self._sync_write(GOAL_POSITION, "<i", goal)
        self._sync_write(TORQUE_ENABLE, "<B", [1] * n)

    def _read_present(self) -> dict[int, bytes]:
        if self.fast:
            try:
                return self.bus.fast_sync_read(PRESENT, 10, self.ids)
            except IndexError as exc:  # defensive: a malformed reply must never escape as IndexError
                raise HardwareError(f"{self.port}: malformed fast-sync-read reply ({exc})",
                                    "set dynamixel.fast_sync_read: false in the hand file") from None
        return self.bus.sync_read(PRESENT, 10, self.ids)

    def read_state(self) -> HandState:
        raw = self._read_present()
        stamp = time.monotonic()
        current = [struct.unpack_from("<h", raw[i], 0)[0] for i in self.ids]
        ticks = [struct.unpack_from("<i", raw[i], 6)[0] for i in self.ids]
        return HandState(q=self._checked(self.mapper.to_rad(ticks), ticks), effort=self.mapper.reorder(current), effort_kind="current_mA",
                         stamp=stamp, fingerprint=b"".join(raw[i] for i in self.ids), native=ticks)

    def write_targets(self, q: np.ndarray) -> None:
        self._sync_write(GOAL_POSITION, "<i", self._native_targets(q))

    def hold(self) -> None:
        """Goal := measured (checked for plausibility, clipped into the joint limits)."""
        self.write_targets(self.read_state().q)

    def relax(self) -> None:
        """Torque off: the servos are backdrivable, the fingers fall open under their own weight."""
        self.torque_off()

    def torque_off(self) -> None:
        self._sync_write(TORQUE_ENABLE, "<B", [0] * len(self.ids))
