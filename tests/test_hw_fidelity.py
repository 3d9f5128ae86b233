"""Fake devices behave like the real ones where that matters (issue 10 item 11), and the Dynamixel driver
resynchronises on junk before a status header as the ROBOTIS SDK does."""

from __future__ import annotations

import struct
import time

import pytest

from dgz_cli.hw.dynamixel import BROADCAST, MAX_JUNK, PING, STATUS, DynamixelBus, packet
from dgz_cli.hw.errors import BusCrcError, BusTimeout, DeviceFault
from dgz_cli.hw.fakes.dynamixel import GOAL_POS, TORQUE, DynamixelFake
from dgz_cli.hw.fakes.modbus import ModbusFake
from dgz_cli.hw.modbus_rtu import with_crc
from dgz_cli.hw.serial_port import open_serial


class Wire:
    def __init__(self, reply: bytes) -> None:
        self.rx, self.sent = bytearray(reply), []

    def reset_input_buffer(self) -> None:
        pass

    def write(self, data: bytes) -> None:
        self.sent.append(bytes(data))

    def read(self, n: int) -> bytes:
        out = bytes(self.rx[:n])
        del self.rx[:n]
        return out


PING_REPLY = packet(5, STATUS, bytes([0]) + struct.pack("<HB", 1220, 52))


@pytest.mark.parametrize("junk", [b"\x00", b"\x00\x11\x22", b"\xff", b"\xff\xff", b"\xff\xff\xfd",
                                  b"\xff\xff\xfd\x01", b"\xff\xff\xff\xfd", bytes(range(100)),
                                  b"\xfd\x00" * 40, PING_REPLY[3:]],
                         ids=["one-byte", "three-bytes", "ff", "ff-ff", "partial-header", "header-like",
                              "ff-ff-ff-fd", "100-bytes", "fd00-pairs", "tail-of-a-late-reply"])
def test_driver_resynchronises_on_junk_before_the_header(junk: bytes):
    assert DynamixelBus(Wire(junk + PING_REPLY), "p").ping(5) == (1220, 52)


def test_junk_without_a_header_is_a_bus_error_not_a_hang():
    with pytest.raises(BusCrcError, match="noise"):
        DynamixelBus(Wire(bytes(range(50))), "p").ping(5)
    with pytest.raises(BusCrcError, match="no status header"):
        DynamixelBus(Wire(b"\x00" * (MAX_JUNK + 50) + PING_REPLY), "p").ping(5)
    with pytest.raises(BusTimeout, match="incomplete"):
        DynamixelBus(Wire(b"\xff\xff"), "p").ping(5)
    with pytest.raises(BusTimeout, match="no status packet"):
        DynamixelBus(Wire(b""), "p").ping(5)


@pytest.fixture
def dxl():
    fake = DynamixelFake(ids=[0, 1, 2]).start()
    ser = open_serial(fake.port, 4000000, 0.05)
    yield fake, DynamixelBus(ser, fake.port, 4000000), ser
    ser.close()
    fake.stop()


def test_fake_dynamixel_refuses_eeprom_writes_while_torque_is_on(dxl):
    fake, bus, _ = dxl
    bus.write(1, 11, b"\x03")  # operating mode, torque off: fine
    bus.write(1, TORQUE, b"\x01")
    with pytest.raises(DeviceFault, match="ID 1 reports access error"):
        bus.write(1, 11, b"\x04")
    assert fake.tables[1][11] == 3
    bus.write(1, GOAL_POS, struct.pack("<i", 2100))  # RAM stays writable
    bus.write(1, TORQUE, b"\x00")
    bus.write(1, 11, b"\x04")
    assert fake.tables[1][11] == 4


@pytest.mark.parametrize("addr, length", [(699, 4), (700, 1), (1000, 2), (0, 701)])
def test_fake_dynamixel_refuses_reads_past_the_control_table(dxl, addr: int, length: int):
    _, bus, _ = dxl
    with pytest.raises(DeviceFault, match="access error"):
        bus.read(2, addr, length)


def test_fake_dynamixel_answers_broadcast_ping(dxl):
    fake, bus, ser = dxl
    ser.reset_input_buffer()
    ser.write(packet(BROADCAST, PING))
    ids = [bus.receive(0)[0] for _ in range(3)]
    assert ids == [0, 1, 2]


# --------------------------------------------------------------------------------------------
# Modbus fake: the spec's exception codes, FC16 byte count, unsupported functions, broadcast writes
# --------------------------------------------------------------------------------------------

@pytest.fixture
def mb():
    fake = ModbusFake(slave=1)
    fake.holding = {a: a for a in range(200)}
    fake.input = {a: 1000 + a for a in range(200)}
    fake.start()
    ser = open_serial(fake.port, 115200, 0.2)
    yield fake, ser
    ser.close()
    fake.stop()


def _ask(ser, body: bytes) -> bytes:
    ser.reset_input_buffer()
    ser.write(with_crc(body))
    time.sleep(0.05)
    return ser.read(256)


@pytest.mark.parametrize("fc", [0x03, 0x04])
@pytest.mark.parametrize("count", [0, 126, 0xFFFF])
def test_modbus_fake_quantity_out_of_range_is_exception_3(mb, fc: int, count: int):
    _, ser = mb
    reply = _ask(ser, struct.pack(">BBHH", 1, fc, 0, count))
    assert reply[:3] == bytes([1, fc | 0x80, 3])


def test_modbus_fake_bad_address_is_exception_2(mb):
    _, ser = mb
    assert _ask(ser, struct.pack(">BBHH", 1, 0x03, 500, 2))[:3] == bytes([1, 0x83, 2])


@pytest.mark.parametrize("count, byte_count", [(2, 2), (2, 6), (1, 0), (124, 248)])
def test_modbus_fake_fc16_byte_count_or_quantity_mismatch_is_exception_3(mb, count: int, byte_count: int):
    fake, ser = mb
    before = dict(fake.holding)
    body = struct.pack(">BBHHB", 1, 0x10, 10, count, byte_count) + bytes(byte_count)
    assert _ask(ser, body)[:3] == bytes([1, 0x90, 3])
    assert fake.holding == before and not fake.writes


@pytest.mark.parametrize("body", [bytes([1, 0x0F, 0, 0, 0, 8, 1, 0xFF]), bytes([1, 0x2B, 0x0E, 0x01, 0x00]),
                                  bytes([1, 0x01, 0, 0, 0, 8]), bytes([1, 0x05, 0, 0, 0xFF, 0])],
                         ids=["fc15", "fc43", "fc01", "fc05"])
def test_modbus_fake_unsupported_functions_are_exception_1(mb, body: bytes):
    _, ser = mb
    assert _ask(ser, body)[:3] == bytes([1, body[1] | 0x80, 1])


def test_modbus_fake_executes_broadcast_writes_silently(mb):
    fake, ser = mb
    assert _ask(ser, struct.pack(">BBHH", 0, 0x06, 7, 4242)) == b""
    assert fake.holding[7] == 4242
    assert _ask(ser, struct.pack(">BBHHB", 0, 0x10, 20, 2, 4) + struct.pack(">HH", 1, 2)) == b""
    assert fake.holding[20] == 1 and fake.holding[21] == 2
