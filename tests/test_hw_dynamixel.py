"""Dynamixel Protocol 2.0: exact packets, stuffing, status parsing, fast-sync-read and its fallback."""

from __future__ import annotations

import struct

import pytest

from dgz_cli.hw.dynamixel import BROADCAST, STATUS, DynamixelBus, crc16, packet, stuff, unstuff
from dgz_cli.hw.errors import BusCrcError, BusTimeout, DeviceFault
from dgz_cli.hw.fakes.dynamixel import DynamixelFake
from dgz_cli.hw.serial_port import open_serial


def crc_bitwise(data: bytes) -> int:
    crc = 0
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def test_ping_packet_id1():
    assert packet(1, 0x01) == bytes.fromhex("FF FF FD 00 01 03 00 01 19 4E")


def test_read_present_position_packet():
    # e-manual example: read 4 bytes at 132 from ID 1.
    assert packet(1, 0x02, struct.pack("<HH", 132, 4)) == bytes.fromhex("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15")


def test_crc_table_matches_bitwise():
    for data in (b"", b"\x00", bytes(range(40)), b"\xff\xff\xfd\x00\x01\x03\x00\x01"):
        assert crc16(data) == crc_bitwise(data)


def test_byte_stuffing_counts_in_length_and_round_trips():
    params = b"\x74\x00\xff\xff\xfd\x01"
    pkt = packet(3, 0x03, params)
    assert b"\xff\xff\xfd\xfd\x01" in pkt
    assert struct.unpack("<H", pkt[5:7])[0] == 1 + len(params) + 1 + 2  # inst + stuffed params + crc
    assert unstuff(stuff(params)) == params


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


def test_status_parsing_and_errors():
    bus = DynamixelBus(Wire(packet(5, STATUS, bytes([0]) + struct.pack("<HB", 1220, 52))), "/dev/ttyUSB0")
    assert bus.ping(5) == (1220, 52)
    with pytest.raises(DeviceFault, match="ID 5 reports data range error"):
        DynamixelBus(Wire(packet(5, STATUS, bytes([4]))), "p").write(5, 116, b"\0\0\0\0")
    with pytest.raises(DeviceFault, match="hardware alert"):
        DynamixelBus(Wire(packet(5, STATUS, bytes([0x80]))), "p").write(5, 116, b"\0\0\0\0")
    bad = bytearray(packet(5, STATUS, bytes([0]) + struct.pack("<HB", 1220, 52)))
    bad[-1] ^= 0xFF
    with pytest.raises(BusCrcError, match="CRC error"):
        DynamixelBus(Wire(bytes(bad)), "p").ping(5)
    with pytest.raises(BusTimeout, match=r"/dev/ttyUSB0: no status packet from Dynamixel ID 9 at 4000000 baud"):
        DynamixelBus(Wire(b""), "/dev/ttyUSB0", 4000000).ping(9)


def test_sync_write_wire_format():
    wire = Wire(b"")
    DynamixelBus(wire, "p").sync_write(116, 4, {0: struct.pack("<i", 2048), 1: struct.pack("<i", 100)})
    (pkt,) = wire.sent
    assert pkt[4] == BROADCAST and pkt[7] == 0x83
    assert pkt[8:12] == struct.pack("<HH", 116, 4)
    assert pkt[12:22] == bytes([0]) + struct.pack("<i", 2048) + bytes([1]) + struct.pack("<i", 100)


@pytest.fixture
def fake_bus():
    fakes = []

    def make(**kw):
        fake = DynamixelFake(ids=[0, 1, 2], **kw).start()
        ser = open_serial(fake.port, 4000000, 0.05)
        fakes.append((fake, ser))
        return fake, DynamixelBus(ser, fake.port, 4000000)

    yield make
    for fake, ser in fakes:
        ser.close()
        fake.stop()


def test_round_trip_against_fake(fake_bus):
    fake, bus = fake_bus()
    assert bus.ping(1) == (1220, 52)
    bus.write(2, 116, struct.pack("<i", 1234))
    assert struct.unpack("<i", bus.read(2, 116, 4))[0] == 1234
    data = bus.fast_sync_read(126, 10, [0, 1, 2])
    assert sorted(data) == [0, 1, 2] and all(len(v) == 10 for v in data.values())
    assert [struct.unpack_from("<i", v, 6)[0] for v in data.values()] == [2048, 2048, 2048]
    assert bus.sync_read(132, 4, [0, 1, 2]) == {i: struct.pack("<i", 2048) for i in (0, 1, 2)}
    with pytest.raises(BusTimeout):
        bus.ping(7)  # absent id: silence, like a real bus


def test_fast_sync_read_unsupported_times_out(fake_bus):
    fake, bus = fake_bus(fast_sync=False)
    with pytest.raises(BusTimeout):
        bus.fast_sync_read(126, 10, [0, 1, 2])
    assert len(bus.sync_read(126, 10, [0, 1, 2])) == 3
