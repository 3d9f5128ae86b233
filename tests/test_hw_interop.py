"""Packet-level interop (issue 10 item 11): the fakes answer the official clients, ROBOTIS ``dynamixel-sdk``
(Protocol 2.0) and ``pymodbus`` (RTU framer), byte for byte as the drivers' own tests expect. Both clients
are test dependencies (``pip install -e '.[test]'``); nothing here is skipped."""

from __future__ import annotations

import struct
import time

import dynamixel_sdk.port_handler
import pytest
from dynamixel_sdk import COMM_RX_TIMEOUT, COMM_SUCCESS, GroupBulkRead, GroupSyncRead, GroupSyncWrite, PacketHandler, \
    PortHandler
from pymodbus.client import ModbusSerialClient
from pymodbus.exceptions import ModbusIOException
from pymodbus.framer import FramerType
from pymodbus.pdu.register_message import ReadHoldingRegistersRequest, WriteMultipleRegistersRequest

from dgz_cli.hw.config import load_hand_config
from dgz_cli.hw.fakes import fake_for
from dgz_cli.hw.fakes.dynamixel import ACCESS_ERROR, GOAL_POS, MODEL_XC330_T288, PRESENT_POS, TORQUE

HW_ALERT = 0x80  # Protocol 2.0 status error byte: hardware alert bit

# -- Dynamixel Protocol 2.0 (LEAP hand) ------------------------------------------------------------


@pytest.fixture
def leap(monkeypatch):
    # the SDK's reply timeout is 2 x its USB latency timer (16 ms) + 2 ms; at 50 ms (102 ms) one reply of the
    # thread-run fake still missed it on a 2-core CI machine, so 150 ms (302 ms); only the expected timeouts wait it
    monkeypatch.setattr(dynamixel_sdk.port_handler, "LATENCY_TIMER", 150)
    cfg = load_hand_config("leap")
    fake = fake_for(cfg, rate=1e9).start()  # motors reach their goal at the next physics step
    port = PortHandler(fake.port)
    try:
        assert port.openPort()
        assert port.setBaudRate(cfg.port.baudrate)
        yield fake, port, PacketHandler(2.0), [c.id for c in cfg.channels]
    finally:
        port.closePort()
        fake.stop()


def test_sdk_pings_every_motor_and_nobody_answers_an_absent_id(leap):
    fake, port, ph, ids = leap
    assert len(ids) == 16
    for i in ids:
        model, result, error = ph.ping(port, i)
        assert (model, result, error) == (MODEL_XC330_T288, COMM_SUCCESS, 0), (i, ph.getTxRxResult(result))
    _, result, _ = ph.ping(port, 200)
    assert result == COMM_RX_TIMEOUT
    found, result = ph.broadcastPing(port)  # every motor answers, back to back (the SDK waits ~0.8 s)
    assert result == COMM_SUCCESS and found == {i: [MODEL_XC330_T288, 52] for i in ids}


def test_sdk_reads_position_and_writes_goal(leap):
    fake, port, ph, ids = leap
    pos, result, error = ph.read4ByteTxRx(port, 3, PRESENT_POS)
    assert (pos, result, error) == (2048, COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 3, TORQUE, 1) == (COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 3, GOAL_POS, 3000) == (COMM_SUCCESS, 0)
    assert ph.read4ByteTxRx(port, 3, GOAL_POS) == (3000, COMM_SUCCESS, 0)
    assert fake.goal(3) == 3000 and fake.torque(3)
    time.sleep(0.02)
    assert ph.read4ByteTxRx(port, 3, PRESENT_POS) == (3000, COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 3, 7) == (3, COMM_SUCCESS, 0)  # ID register


def test_sdk_byte_stuffing_round_trips(leap):
    """A value whose bytes spell the header (FF FF FD) is stuffed by the SDK, unstuffed by the fake, and back."""
    fake, port, ph, _ = leap
    value = 0x00FDFFFF  # little-endian FF FF FD 00
    assert ph.write4ByteTxRx(port, 5, GOAL_POS, value) == (COMM_SUCCESS, 0)
    assert fake.goal(5) == value
    assert ph.read4ByteTxRx(port, 5, GOAL_POS) == (value, COMM_SUCCESS, 0)


def test_sdk_sync_read_fast_sync_read_and_bulk_read(leap):
    fake, port, ph, ids = leap
    for i in ids:
        struct.pack_into("<i", fake.tables[i], GOAL_POS, 1000 + i)
    group = GroupSyncRead(port, ph, GOAL_POS, 4)
    for i in ids:
        assert group.addParam(i)
    assert group.txRxPacket() == COMM_SUCCESS
    assert all(group.isAvailable(i, GOAL_POS, 4) for i in ids)
    assert [group.getData(i, GOAL_POS, 4) for i in ids] == [1000 + i for i in ids]
    assert group.fastSyncRead() == COMM_SUCCESS
    assert [group.getData(i, GOAL_POS, 4) for i in ids] == [1000 + i for i in ids]

    bulk = GroupBulkRead(port, ph)
    assert bulk.addParam(0, PRESENT_POS, 4) and bulk.addParam(7, GOAL_POS, 4) and bulk.addParam(15, 7, 1)
    assert bulk.txRxPacket() == COMM_SUCCESS
    assert (bulk.getData(0, PRESENT_POS, 4), bulk.getData(7, GOAL_POS, 4), bulk.getData(15, 7, 1)) == (2048, 1007, 15)


def test_sdk_sync_write_reaches_every_motor(leap):
    fake, port, ph, ids = leap
    group = GroupSyncWrite(port, ph, GOAL_POS, 4)
    for i in ids:
        assert group.addParam(i, (500 + 10 * i).to_bytes(4, "little"))
    assert group.txPacket() == COMM_SUCCESS
    assert ph.read4ByteTxRx(port, ids[-1], GOAL_POS) == (500 + 10 * ids[-1], COMM_SUCCESS, 0)  # after the write
    assert [fake.goal(i) for i in ids] == [500 + 10 * i for i in ids]


def test_sdk_sees_the_fakes_error_statuses(leap):
    fake, port, ph, _ = leap
    # a read past the control table: access error, no data
    _, result, error = ph.readTxRx(port, 2, 690, 20)
    assert (result, error) == (COMM_SUCCESS, ACCESS_ERROR)
    # an EEPROM write (operating mode, address 11) with torque on: access error, table unchanged
    assert ph.write1ByteTxRx(port, 2, TORQUE, 1) == (COMM_SUCCESS, 0)
    result, error = ph.write1ByteTxRx(port, 2, 11, 5)
    assert (result, error) == (COMM_SUCCESS, ACCESS_ERROR)
    assert "not available to target address" in ph.getRxPacketError(error)
    assert ph.read1ByteTxRx(port, 2, 11) == (3, COMM_SUCCESS, 0)
    # with torque off the same write is accepted
    assert ph.write1ByteTxRx(port, 2, TORQUE, 0) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, 11, 5) == (COMM_SUCCESS, 0)
    assert ph.read1ByteTxRx(port, 2, 11) == (5, COMM_SUCCESS, 0)
    # hardware alert: the status error byte has bit 7 set, which the SDK reports as such
    fake.fault = "exception"
    _, result, error = ph.ping(port, 2)
    assert result == COMM_SUCCESS and error & HW_ALERT
    assert "hardware" in ph.getRxPacketError(error).lower()
    # a corrupted checksum is a CRC failure to the SDK, not data
    fake.fault = "crc"
    _, result, _ = ph.read4ByteTxRx(port, 2, PRESENT_POS)
    assert result != COMM_SUCCESS


# -- Modbus RTU (Inspire RH56, BrainCo Revo2) ------------------------------------------------------


class _Unchecked(ReadHoldingRegistersRequest):
    """FC03 with whatever quantity: pymodbus refuses to encode one outside 1..125 itself."""

    def encode(self) -> bytes:
        return struct.pack(">HH", self.address, self.count)


def _modbus(hand: str):
    cfg = load_hand_config(hand)
    fake = fake_for(cfg, rate=1e9).start()
    client = ModbusSerialClient(fake.port, framer=FramerType.RTU, baudrate=115200, timeout=0.3, retries=0)
    return cfg, fake, client


@pytest.fixture(params=["inspire", "revo2"])
def modbus_hand(request):
    cfg, fake, client = _modbus(request.param)
    try:
        assert client.connect()
        yield request.param, cfg.slave_id, fake, client
    finally:
        client.close()
        fake.stop()


# (set-point register, feedback function, feedback register, a register that does not exist) per hand
MAPS = {"inspire": (1486, "holding", 1546, 5000), "revo2": (1022, "input", 2000, 5000)}


def _feedback(client, hand: str, slave: int):
    _, bank, reg, _ = MAPS[hand]
    read = client.read_holding_registers if bank == "holding" else client.read_input_registers
    return read(reg, count=6, device_id=slave)


def test_pymodbus_reads_identity_and_feedback(modbus_hand):
    hand, slave, fake, client = modbus_hand
    if hand == "inspire":
        rr = client.read_holding_registers(1000, count=1, device_id=slave)  # ID register
        assert not rr.isError() and rr.registers == [slave]
        assert _feedback(client, hand, slave).registers == [1000] * 6  # open
    else:
        rr = client.read_holding_registers(901, count=1, device_id=slave)  # SKU
        assert not rr.isError() and rr.registers == [0x0202]
        fw = client.read_input_registers(3000, count=10, device_id=slave)
        assert b"".join(struct.pack(">H", r) for r in fw.registers).rstrip(b"\x00") == b"2.0.5"
        assert _feedback(client, hand, slave).registers == [0] * 6


def test_pymodbus_write_multiple_then_read_back(modbus_hand):
    hand, slave, fake, client = modbus_hand
    setpoint = MAPS[hand][0]
    values = [100, 200, 300, 400, 500, 600]
    words = values if hand == "inspire" else [w for v in values for w in (v, 0)][:12]  # Revo2: (pos, speed) pairs
    wr = client.write_registers(setpoint, words, device_id=slave)
    assert not wr.isError() and (wr.address, wr.count) == (setpoint, len(words))
    rr = client.read_holding_registers(setpoint, count=len(words), device_id=slave)
    assert rr.registers == words
    time.sleep(0.02)
    assert _feedback(client, hand, slave).registers == values


def test_pymodbus_gets_the_spec_exception_codes(modbus_hand):
    hand, slave, fake, client = modbus_hand
    for count in (0, 126):  # illegal data value: quantity out of 1..125
        rr = client.execute(False, _Unchecked(address=MAPS[hand][0], count=count, dev_id=slave))
        assert rr.isError() and rr.function_code == 0x83 and rr.exception_code == 3, count
    # FC16 with 124 registers (the spec allows 1..123)
    wr = client.execute(False, WriteMultipleRegistersRequest(address=MAPS[hand][0], registers=[0] * 124, dev_id=slave))
    assert wr.isError() and wr.function_code == 0x90 and wr.exception_code == 3
    # an address the device does not have: illegal data address
    rr = client.read_holding_registers(MAPS[hand][3], count=1, device_id=slave)
    assert rr.isError() and rr.exception_code == 2
    # unsupported functions (FC43 read device identification, FC01 read coils): illegal function
    rr = client.read_device_information(device_id=slave)
    assert rr.isError() and rr.function_code == 0xAB and rr.exception_code == 1
    rr = client.read_coils(0, count=1, device_id=slave)
    assert rr.isError() and rr.function_code == 0x81 and rr.exception_code == 1
    # the device-failure switch: every request refused with exception 4
    fake.fault = "exception"
    rr = client.read_holding_registers(MAPS[hand][0], count=1, device_id=slave)
    assert rr.isError() and rr.exception_code == 4


def test_pymodbus_broadcast_write_is_applied_silently_and_other_slaves_are_ignored(modbus_hand):
    hand, slave, fake, client = modbus_hand
    setpoint = MAPS[hand][0]
    before = fake.requests
    client.write_registers(setpoint, [7], device_id=0, no_response_expected=True)
    deadline = time.monotonic() + 1.0
    while fake.requests == before and time.monotonic() < deadline:
        time.sleep(0.005)
    assert client.read_holding_registers(setpoint, count=1, device_id=slave).registers == [7]
    other = (slave % 247) + 1
    with pytest.raises(ModbusIOException):  # another slave's address: no answer, pymodbus times out
        client.read_holding_registers(setpoint, count=1, device_id=other)
