"""Modbus RTU master: exact wire bytes, reply parsing, error mapping (in memory, no pty)."""

from __future__ import annotations

import pytest

from dgz_cli.hw.errors import BusCrcError, BusTimeout, DeviceFault, Disconnected
from dgz_cli.hw.modbus_rtu import (
    ModbusMaster,
    crc16,
    crc_ok,
    read_request,
    registers_to_ascii,
    to_signed,
    with_crc,
    write_multiple_request,
    write_single_request,
)


def crc_bitwise(data: bytes) -> int:
    """Reference CRC straight from the Modbus spec (bit by bit, poly 0xA001, init 0xFFFF)."""
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            lsb = crc & 1
            crc >>= 1
            if lsb:
                crc ^= 0xA001
    return crc


class Wire:
    """A pyserial-like transport: records what is written, serves canned bytes to read()."""

    def __init__(self, reply: bytes = b"", fail: Exception | None = None) -> None:
        self.sent, self.rx, self.fail = [], bytearray(reply), fail

    def reset_input_buffer(self) -> None:
        pass

    def write(self, data: bytes) -> None:
        if self.fail:
            raise self.fail
        self.sent.append(bytes(data))

    def read(self, n: int) -> bytes:
        out = bytes(self.rx[:n])
        del self.rx[:n]
        return out


def test_crc_reference_frames():
    # The classic reference frame: read 1 holding register at 0 from slave 1 -> CRC bytes 84 0A.
    assert with_crc(bytes.fromhex("010300000001")) == bytes.fromhex("010300000001840A")
    body = bytes.fromhex("0103060A0006")
    assert crc16(body) == crc_bitwise(body) == 0x42E5


def test_fc03_read_6_registers_from_1546_slave_1():
    # 1546 = 0x060A; 6 = 0x0006; CRC 0x42E5 sent low byte first (E5 42), checked bit by bit above.
    assert read_request(1, 3, 1546, 6) == bytes.fromhex("01 03 06 0A 00 06 E5 42")


def test_write_frames():
    body = bytes.fromhex("7F 06 03 A9 00 00")  # Revo2 right, unit mode (937) := 0
    assert write_single_request(127, 937, 0) == body + crc_bitwise(body).to_bytes(2, "little")
    body = bytes.fromhex("01 10 05 CE 00 06 0C") + bytes.fromhex("03E8") * 6  # Inspire ANGLE_SET all open
    assert write_multiple_request(1, 1486, [1000] * 6) == body + crc_bitwise(body).to_bytes(2, "little")
    assert write_multiple_request(1, 1486, [-1])[7:9] == b"\xff\xff"  # -1 = "no change" on the Inspire


def test_read_parses_reply_and_sends_exact_request():
    wire = Wire(with_crc(bytes([1, 3, 12]) + b"".join(v.to_bytes(2, "big") for v in (1000, 900, 0, 65535, 5, 6))))
    m = ModbusMaster(wire, "/dev/ttyFAKE")
    assert m.read_holding(1, 1546, 6) == [1000, 900, 0, 65535, 5, 6]
    assert wire.sent == [bytes.fromhex("01 03 06 0A 00 06 E5 42")]
    assert to_signed([65535, 32768, 5]) == [-1, -32768, 5]


def test_write_multiple_checks_echo():
    req = write_multiple_request(1, 1486, [1, 2])
    m = ModbusMaster(Wire(with_crc(req[:6])), "p")
    m.write_multiple(1, 1486, [1, 2])
    with pytest.raises(BusCrcError, match="echoed a different write"):
        ModbusMaster(Wire(with_crc(bytes.fromhex("01 10 05 CF 00 02"))), "p").write_multiple(1, 1486, [1, 2])


def test_exception_reply_raises_device_fault_with_code_name():
    m = ModbusMaster(Wire(with_crc(bytes([127, 0x83, 4]))), "/dev/ttyUSB7")
    with pytest.raises(DeviceFault) as info:
        m.read_holding(127, 901, 1)
    assert "/dev/ttyUSB7" in info.value.message and "exception 4 (slave device failure)" in info.value.message
    assert info.value.hint
    assert m.stats.exceptions == 1


def test_timeout_and_partial_reply():
    m = ModbusMaster(Wire(b""), "/dev/ttyUSB0", 460800)
    with pytest.raises(BusTimeout, match=r"/dev/ttyUSB0: no reply from Modbus slave 1 \(register 1546\) at 460800"):
        m.read_holding(1, 1546, 6)
    with pytest.raises(BusTimeout, match="incomplete reply"):
        ModbusMaster(Wire(bytes([1, 3, 12, 0, 1])), "p").read_holding(1, 1546, 6)


def test_crc_error_and_foreign_header():
    good = with_crc(bytes([1, 3, 2, 0, 7]))
    with pytest.raises(BusCrcError, match="CRC error"):
        ModbusMaster(Wire(good[:-1] + bytes([good[-1] ^ 1])), "p").read_holding(1, 0, 1)
    with pytest.raises(BusCrcError, match="unexpected reply header"):
        ModbusMaster(Wire(with_crc(bytes([2, 3, 2, 0, 7]))), "p").read_holding(1, 0, 1)
    assert crc_ok(good) and not crc_ok(good[:-1] + b"\x00")


def test_os_error_is_a_disconnect():
    with pytest.raises(Disconnected, match="serial port failed"):
        ModbusMaster(Wire(fail=OSError(5, "Input/output error")), "/dev/ttyUSB0").read_holding(1, 0, 1)


def test_register_ascii_and_bounds():
    assert registers_to_ascii([0x322E, 0x302E, 0x3500, 0]) == "2.0.5"
    with pytest.raises(ValueError):
        ModbusMaster(Wire(), "p").read_holding(1, 0, 126)
