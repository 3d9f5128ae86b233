"""A Modbus RTU slave on a pty: holding and input register banks, FC03/04/06/16, exception replies as the
Modbus spec gives them (3 for a bad quantity or byte count, 2 for a bad address, 1 for FC15/FC43 and other
unsupported functions), broadcast writes executed silently."""

from __future__ import annotations

import struct

from dgz_cli.hw.fakes.base import PtyFake
from dgz_cli.hw.modbus_rtu import crc_ok, with_crc


class ModbusFake(PtyFake):
    """Subclasses fill ``holding``/``input`` (register → uint16) and override ``on_write``/``refresh``."""

    def __init__(self, slave: int, **kw) -> None:
        super().__init__(**kw)
        self.slave = slave
        self.holding: dict[int, int] = {}
        self.input: dict[int, int] = {}
        self.writes: list[tuple[int, list[int]]] = []

    def take_frame(self, buf: bytearray) -> bytes | None:
        while len(buf) >= 7:
            fc = buf[1]
            if fc in (0x0F, 0x10):  # write multiple coils / registers: framed by their byte count
                size = 9 + buf[6]
            elif fc == 0x2B:  # encapsulated interface (read device identification): 7 bytes
                size = 7
            elif fc in (0x03, 0x04, 0x06):
                size = 8
            else:
                size = 8  # unknown function: try the common size, resync on CRC failure
            if len(buf) < size:
                return None
            frame = bytes(buf[:size])
            if crc_ok(frame):
                del buf[:size]
                return frame
            del buf[:1]  # garbage or a corrupted request: a real slave stays silent; resync
        return None

    def handle(self, frame: bytes) -> bytes | None:
        slave, fc = frame[0], frame[1]
        if slave == 0:  # broadcast: a write is executed by every slave, nobody answers
            if fc in (0x06, 0x10) and self.fault != "exception":
                self.handle(bytes([self.slave]) + frame[1:])  # applied; the reply is suppressed
            return None
        if slave != self.slave:
            return None  # another slave's request: say nothing
        if self.fault == "exception":
            return with_crc(bytes([slave, fc | 0x80, 4]))
        if fc in (0x03, 0x04):
            addr, count = struct.unpack(">HH", frame[2:6])
            if not 1 <= count <= 125:
                return with_crc(bytes([slave, fc | 0x80, 3]))  # illegal data value (the spec's order: quantity first)
            self.refresh()
            bank = self.holding if fc == 0x03 else self.feedback_bank()
            if any(a not in bank for a in range(addr, addr + count)):
                return with_crc(bytes([slave, fc | 0x80, 2]))
            regs = [bank[a] & 0xFFFF for a in range(addr, addr + count)]
            return with_crc(bytes([slave, fc, 2 * count]) + struct.pack(f">{count}H", *regs))
        if fc == 0x06:
            addr, value = struct.unpack(">HH", frame[2:6])
            if addr not in self.holding:
                return with_crc(bytes([slave, fc | 0x80, 2]))
            self._write(addr, [value])
            return frame
        if fc == 0x10:
            addr, count = struct.unpack(">HH", frame[2:6])
            if not 1 <= count <= 123 or frame[6] != 2 * count:
                return with_crc(bytes([slave, fc | 0x80, 3]))  # quantity out of range or byte count mismatch
            values = list(struct.unpack(f">{count}H", frame[7:7 + 2 * count]))
            if any(a not in self.holding for a in range(addr, addr + count)):
                return with_crc(bytes([slave, fc | 0x80, 2]))
            self._write(addr, values)
            return with_crc(frame[:6])
        return with_crc(bytes([slave, fc | 0x80, 1]))  # illegal function: FC01/02/05/15/43/... are not supported

    def _write(self, addr: int, values: list[int]) -> None:
        self.writes.append((addr, values))
        for i, v in enumerate(values):
            self.holding[addr + i] = v
        self.on_write(addr, values)

    # -- hooks -------------------------------------------------------------------------------------
    def on_write(self, addr: int, values: list[int]) -> None:
        pass

    def refresh(self) -> None:
        """Copy the simulated state into the feedback registers (unless frozen)."""

    def feedback_bank(self) -> dict[int, int]:
        return self.input


def u16(v: int) -> int:
    return int(v) & 0xFFFF


def ascii_regs(text: str, n: int) -> list[int]:
    raw = text.encode("ascii")[: 2 * n].ljust(2 * n, b"\x00")
    return list(struct.unpack(f">{n}H", raw))
