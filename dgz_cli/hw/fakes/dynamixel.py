"""Fake Dynamixel Protocol 2.0 bus on a pty: one control table (bytearray) per ID, XC330-like addresses.

Implements ping (also broadcast), read, write, sync-read, sync-write, fast-sync-read (switch off with
``fast_sync=False`` to exercise the driver's fallback) and bulk read (0x92: ``ID, address, length`` per
motor; each motor answers with its own status packet in request order, a read past its table with access
error 7; as on a real bus, where each motor waits for the previous one's status packet, the motors after an
absent ID stay silent; a malformed parameter block is not answered). With torque on, a motor moves toward its goal
position at ``rate`` ticks/s; present current carries one tick of deterministic sensor noise.
"""

from __future__ import annotations

import struct

from dgz_cli.hw.dynamixel import (
    BROADCAST,
    BULK_READ,
    FAST_SYNC_READ,
    HEADER,
    PING,
    READ,
    STATUS,
    SYNC_READ,
    SYNC_WRITE,
    WRITE,
    crc16,
    packet,
    unstuff,
)
from dgz_cli.hw.fakes.base import PtyFake, approach

MODEL_XC330_T288 = 1220
TORQUE, GOAL_POS, PRESENT_CURRENT, PRESENT_VEL, PRESENT_POS, HW_ERROR = 64, 116, 126, 128, 132, 70
EEPROM_END = 64  # addresses below are EEPROM: writable only with torque off
ACCESS_ERROR = 7  # status error: write to a locked/undefined address, read past the table


class DynamixelFake(PtyFake):
    name = "dynamixel"

    def __init__(self, ids=range(16), rate: float = 4000.0, fast_sync: bool = True, model: int = MODEL_XC330_T288,
                 start_ticks: int = 2048, **kw) -> None:
        super().__init__(**kw)
        self.rate = rate
        self.fast_sync = fast_sync
        self.tables: dict[int, bytearray] = {}
        self.pos: dict[int, float] = {}
        self._tick = 0
        self.writes: list[tuple[int, int, bytes]] = []  # (id, address, data) of every write instruction
        self.order = list(ids)
        for i in ids:
            t = bytearray(700)
            struct.pack_into("<H", t, 0, model)
            t[6], t[7], t[8], t[11] = 52, i, 6, 3  # firmware, id, baud index, operating mode
            struct.pack_into("<i", t, GOAL_POS, start_ticks)
            self.tables[i] = t
            self.pos[i] = float(start_ticks)
            self._refresh_one(i)

    # -- framing -----------------------------------------------------------------------------------
    def take_frame(self, buf: bytearray) -> bytes | None:
        while True:
            at = buf.find(HEADER)
            if at < 0:
                del buf[:max(0, len(buf) - 3)]
                return None
            del buf[:at]
            if len(buf) < 7:
                return None
            size = 7 + struct.unpack("<H", buf[5:7])[0]
            if len(buf) < size:
                return None
            frame = bytes(buf[:size])
            if crc16(frame[:-2]) == struct.unpack("<H", frame[-2:])[0]:
                del buf[:size]
                return frame
            del buf[:1]

    def _status(self, dxl_id: int, params: bytes = b"", error: int = 0) -> bytes:
        error |= 0x80 if self.fault == "exception" else 0
        return packet(dxl_id, STATUS, bytes([error]) + (params if not error & 0x7F else b""))

    def handle(self, frame: bytes) -> bytes | None:
        dxl_id = frame[4]
        body = unstuff(frame[7:-2])
        inst, params = body[0], body[1:]
        if inst == SYNC_WRITE:
            addr, length = struct.unpack("<HH", params[:4])
            for k in range(4, len(params), length + 1):
                i = params[k]
                if i in self.tables:
                    self._write(i, addr, params[k + 1:k + 1 + length])
            return None
        if inst in (SYNC_READ, FAST_SYNC_READ):
            addr, length = struct.unpack("<HH", params[:4])
            ids = [i for i in params[4:] if i in self.tables]
            if inst == SYNC_READ:
                return b"".join(self._status(i, self._read(i, addr, length)) for i in ids)
            if not self.fast_sync:
                return None  # older firmware: instruction unknown, no answer
            blob = bytearray()
            for i in ids:
                blob += bytes([0x80 if self.fault == "exception" else 0, i]) + self._read(i, addr, length)
                blob += struct.pack("<H", crc16(bytes(blob)))
            return self._fast_packet(bytes(blob[:-2]))
        if inst == BULK_READ:
            return self._bulk_read(params) if dxl_id == BROADCAST else None
        if inst == PING and dxl_id == BROADCAST:  # every motor answers, in ID order (as real ones do)
            return b"".join(self._status(i, bytes(self.tables[i][0:2]) + bytes([self.tables[i][6]]))
                            for i in sorted(self.tables))
        if dxl_id not in self.tables:
            return None
        if inst == PING:
            t = self.tables[dxl_id]
            return self._status(dxl_id, bytes(t[0:2]) + bytes([t[6]]))
        if inst == READ:
            addr, length = struct.unpack("<HH", params[:4])
            if addr + length > len(self.tables[dxl_id]):
                return self._status(dxl_id, error=ACCESS_ERROR)  # past the control table
            return self._status(dxl_id, self._read(dxl_id, addr, length))
        if inst == WRITE:
            return self._status(dxl_id, error=self._write(dxl_id, struct.unpack("<H", params[:2])[0], params[2:]))
        return packet(dxl_id, STATUS, bytes([0x02]))  # instruction error

    def _bulk_read(self, params: bytes) -> bytes | None:
        if not params or len(params) % 5:
            return None  # not a list of (ID, address, length): no motor recognises its part
        out = b""
        for k in range(0, len(params), 5):
            i, addr, length = struct.unpack("<BHH", params[k:k + 5])
            if i not in self.tables:
                break  # the next motors wait for this one's status packet, which never comes
            if addr + length > len(self.tables[i]):
                out += self._status(i, error=ACCESS_ERROR)
            else:
                out += self._status(i, self._read(i, addr, length))
        return out or None

    @staticmethod
    def _fast_packet(params: bytes) -> bytes:
        body = bytes([STATUS]) + params  # not stuffed
        head = HEADER + struct.pack("<BH", BROADCAST, len(body) + 2) + body
        return head + struct.pack("<H", crc16(head))

    # -- control table -----------------------------------------------------------------------------
    def _read(self, dxl_id: int, addr: int, length: int) -> bytes:
        if self.fault != "stale":
            self._refresh_one(dxl_id)
        return bytes(self.tables[dxl_id][addr:addr + length])

    def _write(self, dxl_id: int, addr: int, data: bytes) -> int:
        """Apply a write; the status error code (0, or ACCESS_ERROR as a real motor answers it)."""
        self.writes.append((dxl_id, addr, bytes(data)))
        t = self.tables[dxl_id]
        if addr < EEPROM_END and t[TORQUE] or addr + len(data) > len(t):
            return ACCESS_ERROR  # EEPROM is locked while torque is on; nothing past the control table
        t[addr:addr + len(data)] = data
        return 0

    def torque(self, dxl_id: int) -> bool:
        return bool(self.tables[dxl_id][TORQUE])

    def goal(self, dxl_id: int) -> int:
        return struct.unpack_from("<i", self.tables[dxl_id], GOAL_POS)[0]

    def advance(self, dt: float) -> None:
        for i, t in self.tables.items():
            if t[TORQUE]:
                self.pos[i] = approach(self.pos[i], float(self.goal(i)), self.rate * max(dt, 0.0))

    def _refresh_one(self, dxl_id: int) -> None:
        self._tick += 1
        t = self.tables[dxl_id]
        err = self.goal(dxl_id) - self.pos[dxl_id] if t[TORQUE] else 0.0
        moving = abs(err) >= 1
        current = (int(max(-300, min(300, err))) if moving else 0) + (self.requests % 3)
        struct.pack_into("<h", t, PRESENT_CURRENT, current)
        struct.pack_into("<i", t, PRESENT_VEL, int(self.rate / 60) if moving else 0)
        struct.pack_into("<i", t, PRESENT_POS, int(round(self.pos[dxl_id])))
        if self.corrupted(self.order.index(dxl_id)):
            struct.pack_into("<I", t, PRESENT_POS, self.corrupt_position & 0xFFFFFFFF)
