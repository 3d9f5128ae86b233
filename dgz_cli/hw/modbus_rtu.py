"""A small Modbus RTU master: CRC16 (poly 0xA001 reflected, init 0xFFFF), FC03/04/06/16, exception replies.

Pure Python over any pyserial-like transport (``write``, ``read(n)`` bounded by the port timeout,
``reset_input_buffer``). Why not pymodbus: see docs/deploy.md ("Why an own Modbus master").
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from dgz_cli.hw.errors import BusCrcError, BusTimeout, DeviceFault
from dgz_cli.hw.serial_port import IO_ERRORS, io_error

READ_HOLDING, READ_INPUT, WRITE_SINGLE, WRITE_MULTIPLE = 0x03, 0x04, 0x06, 0x10
EXCEPTIONS = {1: "illegal function", 2: "illegal data address", 3: "illegal data value",
              4: "slave device failure", 5: "acknowledge", 6: "slave device busy", 8: "memory parity error",
              10: "gateway path unavailable", 11: "gateway target failed to respond"}


def _table() -> list[int]:
    out = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        out.append(crc)
    return out


_CRC_TABLE = _table()


def crc16(data: bytes) -> int:
    """Modbus CRC16 (reflected 0x8005 = 0xA001, init 0xFFFF); sent low byte first."""
    crc = 0xFFFF
    for b in data:
        crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ b) & 0xFF]
    return crc


def with_crc(body: bytes) -> bytes:
    return body + struct.pack("<H", crc16(body))


def crc_ok(frame: bytes) -> bool:
    return len(frame) >= 4 and crc16(frame[:-2]) == struct.unpack("<H", frame[-2:])[0]


def read_request(slave: int, function: int, address: int, count: int) -> bytes:
    """FC03/FC04 request frame."""
    return with_crc(struct.pack(">BBHH", slave, function, address, count))


def write_single_request(slave: int, address: int, value: int) -> bytes:
    return with_crc(struct.pack(">BBHH", slave, WRITE_SINGLE, address, value & 0xFFFF))


def write_multiple_request(slave: int, address: int, values: list[int]) -> bytes:
    regs = [int(v) & 0xFFFF for v in values]
    body = struct.pack(">BBHHB", slave, WRITE_MULTIPLE, address, len(regs), 2 * len(regs))
    return with_crc(body + struct.pack(f">{len(regs)}H", *regs))


def to_signed(values: list[int]) -> list[int]:
    return [v - 0x10000 if v >= 0x8000 else v for v in values]


def registers_to_ascii(values: list[int]) -> str:
    raw = b"".join(struct.pack(">H", v) for v in values)
    return raw.split(b"\x00", 1)[0].decode("ascii", errors="replace").strip()


@dataclass
class BusStats:
    requests: int = 0
    timeouts: int = 0
    crc_errors: int = 0
    exceptions: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def errors(self) -> int:
        return self.timeouts + self.crc_errors + self.exceptions


class ModbusMaster:
    """One request at a time; every call either returns the decoded reply or raises a HardwareError."""

    def __init__(self, transport, port: str = "port", baudrate: int | None = None) -> None:
        self.t = transport
        self.port = port
        self.baud = f" at {baudrate} baud" if baudrate else ""
        self.stats = BusStats()

    # -- public API ---------------------------------------------------------------------------------
    def read_holding(self, slave: int, address: int, count: int) -> list[int]:
        return self._read(slave, READ_HOLDING, address, count)

    def read_input(self, slave: int, address: int, count: int) -> list[int]:
        return self._read(slave, READ_INPUT, address, count)

    def write_single(self, slave: int, address: int, value: int) -> None:
        self._transact(slave, WRITE_SINGLE, write_single_request(slave, address, value), address)

    def write_multiple(self, slave: int, address: int, values: list[int]) -> None:
        if not 1 <= len(values) <= 123:
            raise ValueError("FC16 writes 1..123 registers")
        self._transact(slave, WRITE_MULTIPLE, write_multiple_request(slave, address, list(values)), address)

    # -- internals ----------------------------------------------------------------------------------
    def _read(self, slave: int, function: int, address: int, count: int) -> list[int]:
        if not 1 <= count <= 125:
            raise ValueError("FC03/FC04 read 1..125 registers")
        payload = self._transact(slave, function, read_request(slave, function, address, count), address)
        if len(payload) != 2 * count:
            self.stats.crc_errors += 1
            raise BusCrcError(f"{self.port}: slave {slave} sent {len(payload)} bytes for {count} registers "
                              f"at {address}", "check for another master or device on the bus")
        return list(struct.unpack(f">{count}H", payload))

    def _recv(self, n: int) -> bytes:
        try:
            return self.t.read(n)
        except IO_ERRORS as exc:  # serial.SerialException derives from OSError
            raise io_error(self.port, exc) from None

    def _timeout(self, slave: int, address: int, got: bytes) -> BusTimeout:
        self.stats.timeouts += 1
        what = "an incomplete reply" if got else "no reply"
        return BusTimeout(f"{self.port}: {what} from Modbus slave {slave} (register {address}){self.baud}",
                          "check power, RS485 A/B wiring, the slave id and the baud rate in the hand file")

    def _transact(self, slave: int, function: int, request: bytes, address: int) -> bytes:
        self.stats.requests += 1
        try:
            self.t.reset_input_buffer()  # drop leftovers of an earlier garbled reply
            self.t.write(request)
        except IO_ERRORS as exc:
            raise io_error(self.port, exc) from None
        head = self._recv(2)
        if len(head) < 2:
            raise self._timeout(slave, address, head)
        if head[1] == function | 0x80:
            rest = self._recv(3)
            frame = head + rest
            if len(rest) < 3:
                raise self._timeout(slave, address, frame)
            self._check(frame, slave, address)
            self.stats.exceptions += 1
            code = frame[2]
            raise DeviceFault(f"{self.port}: Modbus slave {slave} refused register {address} with exception {code} "
                              f"({EXCEPTIONS.get(code, 'unknown')})",
                              "check the register map for this firmware; exception 4 means the hand reports a "
                              "fault: power-cycle it and clear its errors")
        if head[0] != slave or head[1] != function:
            self.stats.crc_errors += 1
            raise BusCrcError(f"{self.port}: unexpected reply header {head.hex(' ')} to slave {slave} FC{function:02d}",
                              "another device may share the bus with the same id, or the baud rate is wrong")
        if function in (READ_HOLDING, READ_INPUT):
            nb = self._recv(1)
            if not nb:
                raise self._timeout(slave, address, head)
            rest = self._recv(nb[0] + 2)
            frame = head + nb + rest
            if len(rest) < nb[0] + 2:
                raise self._timeout(slave, address, frame)
            self._check(frame, slave, address)
            return frame[3:-2]
        rest = self._recv(6)
        frame = head + rest
        if len(rest) < 6:
            raise self._timeout(slave, address, frame)
        self._check(frame, slave, address)
        if frame[:6] != request[:6]:
            self.stats.crc_errors += 1
            raise BusCrcError(f"{self.port}: slave {slave} echoed a different write ({frame[:6].hex(' ')})",
                              "check for another master on the bus")
        return b""

    def _check(self, frame: bytes, slave: int, address: int) -> None:
        if not crc_ok(frame):
            self.stats.crc_errors += 1
            raise BusCrcError(f"{self.port}: CRC error in the reply from Modbus slave {slave} (register {address})",
                              "check the RS485 cabling, termination and ground; lower the cable length or baud")


__all__ = ["ModbusMaster", "crc16", "with_crc", "crc_ok", "read_request", "write_single_request",
           "write_multiple_request", "to_signed", "registers_to_ascii", "BusStats"]
