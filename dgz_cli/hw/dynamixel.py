"""Dynamixel Protocol 2.0 in pure Python: packets, CRC16 (poly 0x8005, not reflected), byte stuffing, and a
bus with ping / read / write / sync-read / sync-write / fast-sync-read / bulk-read over any pyserial-like
transport.

Instruction packet: ``FF FF FD 00 | ID | LEN (LE, = instruction + params + 2) | INST | params | CRC (LE)``;
``FF FF FD`` inside instruction/params is sent as ``FF FF FD FD``. Status packets carry INST 0x55 and an
error byte. A fast-sync-read answer is one (unstuffed) status packet from ID 0xFE holding, per motor,
``error, id, data, crc`` (the last motor's crc is the packet's).

A complete, valid status packet that does not answer the request in flight — from another ID, or from the
right ID but of another instruction's shape (a late reply to an earlier request) — is discarded and the next
one read, as the ROBOTIS SDK does for a wrong ID; at most ``MAX_STALE`` in a row (counted in
``stats.extra["stale"]``), then it is a bus error. A missing answer after them is a timeout as usual.
"""

from __future__ import annotations

import struct

from dgz_cli.hw.errors import BusCrcError, BusTimeout, DeviceFault
from dgz_cli.hw.modbus_rtu import BusStats
from dgz_cli.hw.serial_port import IO_ERRORS, io_error

HEADER = b"\xff\xff\xfd\x00"
MAX_JUNK = 1024  # bytes skipped before a status header before the reply counts as garbage
MAX_STALE = 8  # stale status packets (late replies to earlier requests) discarded per answer
BROADCAST = 0xFE
PING, READ, WRITE, SYNC_READ, SYNC_WRITE, FAST_SYNC_READ, STATUS = 0x01, 0x02, 0x03, 0x82, 0x83, 0x8A, 0x55
BULK_READ = 0x92
ERRORS = {1: "result fail", 2: "instruction error", 3: "CRC error", 4: "data range error",
          5: "data length error", 6: "data limit error", 7: "access error"}


def _table() -> list[int]:
    out = []
    for i in range(256):
        crc = i << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
        out.append(crc)
    return out


_TABLE = _table()


def crc16(data: bytes, crc: int = 0) -> int:
    """CRC-16 as the Dynamixel 2.0 manual defines it (poly 0x8005, init 0, no reflection)."""
    for b in data:
        crc = ((crc << 8) & 0xFFFF) ^ _TABLE[((crc >> 8) ^ b) & 0xFF]
    return crc


def stuff(data: bytes) -> bytes:
    return data.replace(b"\xff\xff\xfd", b"\xff\xff\xfd\xfd")


def unstuff(data: bytes) -> bytes:
    return data.replace(b"\xff\xff\xfd\xfd", b"\xff\xff\xfd")


def packet(dxl_id: int, inst: int, params: bytes = b"", do_stuff: bool = True) -> bytes:
    body = bytes([inst]) + bytes(params)
    if do_stuff:
        body = stuff(body)
    head = HEADER + struct.pack("<BH", dxl_id, len(body) + 2) + body
    return head + struct.pack("<H", crc16(head))


def sync_params(address: int, length: int, ids) -> bytes:
    return struct.pack("<HH", address, length) + bytes(ids)


class DynamixelBus:
    def __init__(self, transport, port: str = "port", baudrate: int | None = None) -> None:
        self.t = transport
        self.port = port
        self.baud = f" at {baudrate} baud" if baudrate else ""
        self.stats = BusStats()
        self._stale_run = 0

    # -- raw I/O -----------------------------------------------------------------------------------
    def _send(self, pkt: bytes) -> None:
        self.stats.requests += 1
        try:
            self.t.reset_input_buffer()
            self.t.write(pkt)
        except IO_ERRORS as exc:
            raise io_error(self.port, exc) from None

    def _recv(self, n: int) -> bytes:
        try:
            return self.t.read(n)
        except IO_ERRORS as exc:
            raise io_error(self.port, exc) from None

    def _timeout(self, dxl_id: int, got: bytes) -> BusTimeout:
        self.stats.timeouts += 1
        what = "an incomplete status packet" if got else "no status packet"
        return BusTimeout(f"{self.port}: {what} from Dynamixel ID {dxl_id}{self.baud}",
                          "check the motor's power and the daisy chain to it; check its id and baud rate "
                          "(Dynamixel Wizard)")

    def _crc_error(self, dxl_id: int, why: str) -> BusCrcError:
        self.stats.crc_errors += 1
        return BusCrcError(f"{self.port}: {why} in the status packet from Dynamixel ID {dxl_id}",
                           "check the cable and connectors; another program may be using the bus")

    def _find_header(self, dxl_id: int) -> bytes:
        """The first 7 bytes of the next status packet. Bytes before its header (line noise, the tail of a
        late reply) are skipped, as the ROBOTIS SDK does, up to ``MAX_JUNK`` of them."""
        buf = bytearray(self._recv(7))
        junk = 0
        while (at := buf.find(HEADER)) < 0:
            keep = next((k for k in (3, 2, 1) if buf.endswith(HEADER[:k])), 0)  # a header may be starting
            junk += len(buf) - keep
            del buf[:len(buf) - keep]
            if junk > MAX_JUNK:
                raise self._crc_error(dxl_id, f"no status header in {junk} bytes")
            more = self._recv(1)
            if not more:
                raise self._timeout(dxl_id, bytes(buf)) if not junk else self._crc_error(
                    dxl_id, f"{junk} byte(s) of noise and no status header")
            buf += more
        del buf[:at]
        if len(buf) < 7:
            buf += self._recv(7 - len(buf))
        if len(buf) < 7:
            raise self._timeout(dxl_id, bytes(buf))
        return bytes(buf)

    def _receive_raw(self, dxl_id: int, stuffed: bool = True) -> tuple[int, bytes]:
        """One status packet → (id, body from the instruction byte on)."""
        head = self._find_header(dxl_id)
        length = struct.unpack("<H", head[5:7])[0]
        rest = self._recv(length)
        if len(rest) < length or length < 4:
            raise self._timeout(dxl_id, head + rest)
        frame = head + rest
        if crc16(frame[:-2]) != struct.unpack("<H", frame[-2:])[0]:
            raise self._crc_error(dxl_id, "CRC error")
        body = unstuff(rest[:-2]) if stuffed else rest[:-2]
        if body[0] != STATUS:
            raise self._crc_error(dxl_id, f"instruction 0x{body[0]:02X} instead of a status")
        return head[4], body

    def receive(self, dxl_id: int) -> tuple[int, int, bytes]:
        """One status packet → (id, error, params)."""
        got_id, body = self._receive_raw(dxl_id)
        if len(body) < 2:
            raise self._crc_error(dxl_id, "status without an error byte")
        return got_id, body[1], body[2:]

    def _check_error(self, dxl_id: int, error: int) -> None:
        if error:
            self.stats.exceptions += 1
            what = ERRORS.get(error & 0x7F, f"error {error & 0x7F}") if error & 0x7F else "no instruction error"
            alert = "; hardware alert set (overload, overheat or input voltage)" if error & 0x80 else ""
            raise DeviceFault(f"{self.port}: Dynamixel ID {dxl_id} reports {what}{alert}",
                              "read its Hardware Error Status (register 70), let it cool, and power-cycle the hand")

    def _stale(self, dxl_id: int, why: str) -> None:
        """Count one discarded stale status packet; too many in a row is a bus error."""
        n = self.stats.extra.get("stale", 0) + 1
        self.stats.extra["stale"] = n
        self._stale_run += 1
        if self._stale_run > MAX_STALE:
            raise self._crc_error(dxl_id, f"{self._stale_run} stale status packets in a row (last: {why})")

    def _status(self, dxl_id: int, length: int | None = None) -> bytes:
        """The status packet answering the request in flight to ``dxl_id``: its params (``length`` bytes when
        given; an error status carries none). Stale packets (another ID, or another length) are discarded."""
        self._stale_run = 0
        while True:
            got_id, error, params = self.receive(dxl_id)
            if got_id != dxl_id:
                self._stale(dxl_id, f"a status from ID {got_id}")
                continue
            if length is not None and not error & 0x7F and len(params) != length:
                self._stale(dxl_id, f"{len(params)} bytes instead of {length}")
                continue
            self._check_error(dxl_id, error)
            return params

    # -- instructions ------------------------------------------------------------------------------
    def ping(self, dxl_id: int) -> tuple[int, int]:
        """(model number, firmware version)."""
        self._send(packet(dxl_id, PING))
        params = self._status(dxl_id, 3)
        return struct.unpack("<H", params[:2])[0], params[2]

    def read(self, dxl_id: int, address: int, length: int) -> bytes:
        self._send(packet(dxl_id, READ, struct.pack("<HH", address, length)))
        return self._status(dxl_id, length)

    def write(self, dxl_id: int, address: int, data: bytes) -> None:
        self._send(packet(dxl_id, WRITE, struct.pack("<H", address) + bytes(data)))
        self._status(dxl_id, 0)

    def sync_write(self, address: int, length: int, data: dict[int, bytes]) -> None:
        params = struct.pack("<HH", address, length)
        for dxl_id, value in data.items():
            if len(value) != length:
                raise ValueError("sync-write data must all have the given length")
            params += bytes([dxl_id]) + bytes(value)
        self._send(packet(BROADCAST, SYNC_WRITE, params))

    def sync_read(self, address: int, length: int, ids: list[int]) -> dict[int, bytes]:
        self._send(packet(BROADCAST, SYNC_READ, sync_params(address, length, ids)))
        out = {}
        for dxl_id in ids:
            out[dxl_id] = self._status(dxl_id, length)
        return out

    def bulk_read(self, requests: dict[int, tuple[int, int]]) -> dict[int, bytes]:
        """Protocol 2.0 bulk read (0x92): ``{id: (address, length)}`` → ``{id: data}``, one status packet per
        motor in request order."""
        params = b"".join(struct.pack("<BHH", dxl_id, address, length)
                          for dxl_id, (address, length) in requests.items())
        self._send(packet(BROADCAST, BULK_READ, params))
        return {dxl_id: self._status(dxl_id, length) for dxl_id, (_, length) in requests.items()}

    def fast_sync_read(self, address: int, length: int, ids: list[int]) -> dict[int, bytes]:
        self._send(packet(BROADCAST, FAST_SYNC_READ, sync_params(address, length, ids)))
        block = length + 4
        self._stale_run = 0
        while True:
            got_id, body = self._receive_raw(ids[0], stuffed=False)
            params = body[1:]  # error1 id1 data1 crc1 … error_n id_n data_n (the last crc is the packet's)
            if got_id != BROADCAST:
                self._stale(ids[0], f"a status from ID {got_id}, not the broadcast fast-sync-read reply")
            elif len(params) != len(ids) * block - 2:
                self._stale(ids[0], f"a fast-sync-read reply of {len(params)} bytes for {len(ids)} motors")
            else:
                break
        out = {}
        for k, dxl_id in enumerate(ids):
            start = k * block
            if params[start + 1] != dxl_id:
                raise self._crc_error(dxl_id, f"fast-sync-read block {k} is from ID {params[start + 1]}")
            self._check_error(dxl_id, params[start])
            out[dxl_id] = params[start + 2:start + 2 + length]
        return out
