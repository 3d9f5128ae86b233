"""Fake devices behave like the real ones where that matters (issue 10 item 11), and the Dynamixel driver
resynchronises on junk before a status header as the ROBOTIS SDK does and discards stale status packets
(late replies to earlier requests)."""

from __future__ import annotations

import struct
import time

import pytest

from dgz_cli.hw.dynamixel import BROADCAST, BULK_READ, MAX_JUNK, MAX_STALE, PING, STATUS, DynamixelBus, packet
from dgz_cli.hw.errors import BusCrcError, BusTimeout, DeviceFault
from dgz_cli.hw.fakes.dynamixel import GOAL_POS, PRESENT_POS, TORQUE, DynamixelFake
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


def test_bulk_read_packet_matches_the_e_manual():
    # ROBOTIS e-manual, Protocol 2.0 Bulk Read example: ID 1 reads 2 bytes at 144, ID 2 reads 1 byte at 146
    wire = Wire(b"")
    with pytest.raises(BusTimeout):
        DynamixelBus(wire, "p").bulk_read({1: (144, 2), 2: (146, 1)})
    assert wire.sent[0] == bytes.fromhex("FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05")


def test_fake_dynamixel_answers_bulk_read(dxl):
    fake, bus, _ = dxl
    struct.pack_into("<i", fake.tables[2], GOAL_POS, 1234)
    got = bus.bulk_read({2: (GOAL_POS, 4), 0: (0, 2), 1: (PRESENT_POS, 4)})  # a different address/length each
    assert list(got) == [2, 0, 1]
    assert struct.unpack("<i", got[2])[0] == 1234 and struct.unpack("<H", got[0])[0] == 1220
    assert struct.unpack("<i", got[1])[0] == 2048


def test_fake_dynamixel_bulk_read_answers_in_request_order_one_status_per_motor(dxl):
    fake, bus, ser = dxl
    ser.reset_input_buffer()
    ser.write(packet(BROADCAST, BULK_READ, struct.pack("<BHHBHH", 1, 7, 1, 0, 6, 1)))  # ID, firmware: 1 then 0
    assert [bus.receive(0)[::2] for _ in range(2)] == [(1, b"\x01"), (0, b"\x34")]
    assert ser.read(1) == b""  # nothing more


def test_fake_dynamixel_bulk_read_stops_at_an_absent_id_and_refuses_reads_past_the_table(dxl):
    fake, bus, ser = dxl
    with pytest.raises(BusTimeout, match="ID 9"):
        bus.bulk_read({0: (PRESENT_POS, 4), 9: (PRESENT_POS, 4), 1: (PRESENT_POS, 4)})
    ser.reset_input_buffer()
    ser.write(packet(BROADCAST, BULK_READ, struct.pack("<BHHBHHBHH", 0, 132, 4, 9, 132, 4, 1, 132, 4)))
    assert bus.receive(0)[0] == 0
    assert ser.read(1) == b""  # ID 1 waits for ID 9's status, which never comes: silence, as on a real bus
    with pytest.raises(DeviceFault, match="ID 1 reports access error"):
        bus.bulk_read({0: (PRESENT_POS, 4), 1: (699, 4)})
    ser.reset_input_buffer()
    ser.write(packet(BROADCAST, BULK_READ, b"\x00\x84\x00\x04"))  # not a multiple of 5 bytes
    assert ser.read(1) == b""
    ser.write(packet(1, BULK_READ, struct.pack("<BHH", 1, 132, 4)))  # bulk read is broadcast only
    assert ser.read(1) == b""


# --------------------------------------------------------------------------------------------
# Dynamixel driver: a complete, valid status packet that answers an earlier request is discarded
# --------------------------------------------------------------------------------------------

def _status(dxl_id: int, params: bytes = b"", error: int = 0) -> bytes:
    return packet(dxl_id, STATUS, bytes([error]) + params)


READ_REPLY = _status(5, struct.pack("<i", 2100))
STALE = {
    "other-id": _status(3, struct.pack("<i", 77)),
    "other-id-ping": _status(4, struct.pack("<HB", 1220, 52)),
    "same-id-write-ack": _status(5),
    "same-id-ping-reply": PING_REPLY,
    "same-id-2-byte-read": _status(5, b"\x01\x02"),
}


@pytest.mark.parametrize("stale", list(STALE.values()), ids=list(STALE))
def test_driver_discards_a_stale_status_before_a_read_reply(stale: bytes):
    bus = DynamixelBus(Wire(stale + READ_REPLY), "p")
    assert bus.read(5, 132, 4) == struct.pack("<i", 2100)
    assert bus.stats.extra["stale"] == 1 and bus.stats.errors == 0


@pytest.mark.parametrize("stale", [READ_REPLY, _status(9), _status(5, b"\x01")], ids=["read-reply", "other-id", "1-byte"])
def test_driver_discards_a_stale_status_before_a_ping_or_write_reply(stale: bytes):
    assert DynamixelBus(Wire(stale + PING_REPLY), "p").ping(5) == (1220, 52)
    if stale[4] == 5 and len(stale) > 11:  # a same-ID reply with data cannot be the write's acknowledgement
        bus = DynamixelBus(Wire(stale + _status(5)), "p")
        bus.write(5, 116, b"\x00\x00\x00\x00")
        assert bus.stats.extra["stale"] == 1


def test_driver_discards_stale_packets_in_sync_and_fast_sync_read():
    stale = _status(1, b"\xaa")  # a 1-byte answer to an earlier request
    replies = b"".join(_status(i, struct.pack("<i", 100 + i)) for i in (1, 2))
    assert DynamixelBus(Wire(stale + replies), "p").sync_read(132, 4, [1, 2]) == {1: struct.pack("<i", 101),
                                                                                   2: struct.pack("<i", 102)}
    blob = bytearray()
    for i in (1, 2):
        blob += bytes([0, i]) + struct.pack("<i", 100 + i)
        blob += struct.pack("<H", 0)
    fast = DynamixelFake._fast_packet(bytes(blob[:-2]))
    got = DynamixelBus(Wire(_status(1, struct.pack("<i", 7)) + fast), "p").fast_sync_read(132, 4, [1, 2])
    assert got == {1: struct.pack("<i", 101), 2: struct.pack("<i", 102)}
    stale_fast = DynamixelFake._fast_packet(bytes([0, 1]) + b"\x00\x00")  # an earlier fast-sync-read of 2 bytes
    got = DynamixelBus(Wire(stale_fast + fast), "p").fast_sync_read(132, 4, [1, 2])
    assert got == {1: struct.pack("<i", 101), 2: struct.pack("<i", 102)}


def test_stale_packets_without_the_answer_still_fail():
    with pytest.raises(BusTimeout, match="no status packet from Dynamixel ID 5"):
        DynamixelBus(Wire(_status(3, b"\x00" * 4)), "p").read(5, 132, 4)
    with pytest.raises(BusCrcError, match=f"{MAX_STALE + 1} stale status packets in a row"):
        DynamixelBus(Wire(_status(3) * (MAX_STALE + 1) + READ_REPLY), "p").read(5, 132, 4)
    assert DynamixelBus(Wire(_status(3) * MAX_STALE + READ_REPLY), "p").read(5, 132, 4) == struct.pack("<i", 2100)
    with pytest.raises(DeviceFault, match="access error"):  # an error status is not stale: it fails
        DynamixelBus(Wire(_status(5, error=7)), "p").read(5, 132, 4)
    with pytest.raises(BusCrcError, match="CRC error"):  # a corrupted packet is not discarded as stale
        DynamixelBus(Wire(READ_REPLY[:-1] + bytes([READ_REPLY[-1] ^ 1])), "p").read(5, 132, 4)


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
