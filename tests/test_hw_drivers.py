"""Drivers against their pty fakes: identity checks, configuration, tracking, exit actions, faults."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest

from dgz_cli.hw.errors import BusCrcError, BusTimeout, DeviceFault, Disconnected, HardwareError, IdentityError
from dgz_cli.hw.factory import load_hand, make_driver
from dgz_cli.hw.fakes import fake_for
from dgz_cli.hw.fakes.dynamixel import TORQUE


def wait_until(cond, timeout: float = 2.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.005)
    return cond()


@pytest.fixture
def rig():
    opened = []

    def make(hand: str, **fake_kw):
        cfg, spec = load_hand(hand)
        fake = fake_for(cfg, **fake_kw).start()
        driver = make_driver(cfg, spec, fake.port)
        opened.append((driver, fake))
        return driver, fake

    yield make
    for driver, fake in opened:
        driver.close()
        fake.stop()


@pytest.mark.parametrize("hand", ["revo2", "inspire", "leap"])
def test_connect_is_read_only_then_tracks_targets(rig, hand):
    driver, fake = rig(hand)
    info = driver.connect()
    assert info.port == fake.port and info.identity
    if hand == "leap":
        assert not any(fake.torque(i) for i in range(16))
    else:
        assert fake.writes == []  # identity check and limits are reads only (dry-run safe)
    driver.enable()
    lo, hi = driver.limits()
    spec_lo = np.array([j.lower for j in driver.spec.joints])
    spec_hi = np.array([j.upper for j in driver.spec.joints])
    target = np.maximum(lo, spec_lo) + 0.6 * (np.minimum(hi, spec_hi) - np.maximum(lo, spec_lo))
    driver.write_targets(target)
    assert wait_until(lambda: np.max(np.abs(driver.read_state().q - target)) < 0.01)
    state = driver.read_state()
    assert state.q.shape == state.effort.shape == (len(driver.joint_names),)
    driver.hold()
    assert np.max(np.abs(driver.read_state().q - target)) < 0.01


def test_revo2_identity_and_exit_actions(rig):
    driver, fake = rig("revo2")
    info = driver.connect()
    assert info.identity["serial"] == "FAKE-R2-0001" and info.identity["firmware"] == "2.0.5"
    driver.enable()
    driver.write_targets(np.array([1.0, 0.5, 1.0, 1.0, 1.0, 1.0]))
    assert wait_until(lambda: min(fake.pos) > 400)
    driver.relax()  # opens: normalized 0 on every finger
    assert wait_until(lambda: max(fake.pos) == 0)
    driver.torque_off()
    assert wait_until(lambda: fake.pwm_off)


def test_revo2_wrong_slave_names_port_and_fix(rig):
    cfg, spec = load_hand("revo2")
    fake = fake_for(cfg, slave=126).start()  # a left hand on the bus
    try:
        with pytest.raises(IdentityError) as info:
            make_driver(cfg, spec, fake.port).connect()
        assert fake.port in info.value.message and "slave 127" in info.value.message
        assert "126 is the left hand" in info.value.hint
    finally:
        fake.stop()


START = [300.0, 500.0, 250.0, 700.0, 100.0, 900.0]  # normalized finger positions the fake starts at


def test_revo2_physical_unit_mode_is_read_in_degrees_and_switched_at_enable(rig):
    """Issue 10 item 4: a Revo2 left in physical-unit mode (937 = 1) reports degrees; connect detects it, reads
    convert correctly (same q as in normalized mode), nothing is written until enable(), which switches the
    mode and reads it back before any position goes out."""
    ref, ref_fake = rig("revo2", start=START)
    ref.connect()
    q_ref = ref.read_state().q
    driver, fake = rig("revo2", unit_mode=1, start=START)
    info = driver.connect()
    assert info.identity["unit mode"] == "1" and fake.holding[937] == 1
    assert fake.input[2000 + 1] == round(500 * 90 / 1000)  # the fake reports degrees
    q = driver.read_state().q
    assert np.max(np.abs(q - q_ref)) < np.radians(0.6)  # within half a degree of rounding, not 1000× off
    assert fake.writes == []  # read-only until enable(): a dry run never writes
    driver.enable()
    assert fake.writes == [(937, [0])] and fake.holding[937] == 0
    assert np.max(np.abs(driver.read_state().q - q_ref)) < 1e-9
    target = q_ref + 0.05
    driver.write_targets(target)
    assert wait_until(lambda: np.max(np.abs(driver.read_state().q - target)) < 0.01)


def test_revo2_refuses_positions_in_physical_mode_and_a_mode_that_does_not_switch(rig):
    driver, fake = rig("revo2", unit_mode=1, start=START)
    driver.connect()
    with pytest.raises(IdentityError, match="refusing to write positions: Revo2 is in physical unit mode"):
        driver.write_targets(driver.read_state().q)  # without enable(): would be read as degrees
    with pytest.raises(IdentityError, match="physical unit mode"):
        driver.hold()
    original = fake.on_write

    def stuck(addr, values):  # firmware that ignores the mode write
        original(addr, values)
        fake.holding[937] = 1
    fake.on_write = stuck
    with pytest.raises(IdentityError, match="stays in unit mode 1 after writing 0 to register 937"):
        driver.enable()
    assert [a for a, _ in fake.writes] == [937]  # no position was written
    driver.torque_off()  # the fallback exit action (PWM 0) does not depend on the unit mode
    assert wait_until(lambda: fake.pwm_off)


def test_revo2_unknown_unit_mode_is_refused_at_connect(rig):
    driver, fake = rig("revo2", unit_mode=7)
    with pytest.raises(IdentityError, match="unit mode 7 \\(register 937\\)"):
        driver.connect()
    assert fake.writes == []


def test_revo2_in_physical_mode_deploys_and_dry_runs(rig):
    from dgz_cli.runtime.loop import RunConfig, Runner
    from dgz_cli.runtime.mapping import start_pose
    from dgz_cli.runtime.policy import ClosePolicy
    from dgz_cli.spec.contract import ControlContract, EpisodeProtocol

    contract = ControlContract(episode=EpisodeProtocol(control_hz=100.0, grasp_steps=10, lift_steps=2, hold_s=0.0))
    driver, fake = rig("revo2", unit_mode=1, start=START)
    with driver:
        res = Runner(driver, driver.spec, ClosePolicy(driver.spec), RunConfig(contract=contract, dry_run=True)).run(
            start_pose(driver.spec))
    assert res.ok, res.reason
    assert fake.writes == [] and fake.holding[937] == 1  # a dry run leaves the mode alone
    driver, fake = rig("revo2", unit_mode=1, start=START)
    with driver:
        res = Runner(driver, driver.spec, ClosePolicy(driver.spec), RunConfig(contract=contract)).run(
            start_pose(driver.spec))
    assert res.ok and res.exit_action == "hold", res.reason
    assert fake.writes[0] == (937, [0])
    first = fake.writes[1]  # the ramp's first set-points start where the fingers are (no jump)
    assert first[0] == 1022 and max(abs(first[1][2 * i] - START[i]) for i in range(6)) <= 10


def test_inspire_id_mismatch_and_settings(rig):
    driver, fake = rig("inspire")
    fake.holding[1000] = 3
    with pytest.raises(IdentityError, match="reports id 3"):
        driver.connect()
    fake.holding[1000] = 1
    driver.connect()
    driver.enable()
    assert [fake.holding[1498 + i] for i in range(6)] == [500] * 6
    assert [fake.holding[1522 + i] for i in range(6)] == [500] * 6
    driver.write_targets(np.array([0.5, 0.3, 1.0, 1.0, 1.0, 1.0]))
    assert wait_until(lambda: max(fake.angle) < 1000)
    driver.relax()
    assert wait_until(lambda: min(fake.angle) == 1000)


def test_leap_enable_configures_every_motor(rig):
    driver, fake = rig("leap")
    driver.connect()
    assert driver.info.identity["read"] == "fast-sync-read"
    driver.enable()
    assert wait_until(lambda: all(fake.torque(i) for i in range(16)))  # sync-write has no reply
    for i in range(16):
        t = fake.tables[i]
        assert t[11] == 5 and t[TORQUE] == 1
        assert struct.unpack_from("<HHHH", t, 80)[0] == 200  # D gain
        assert struct.unpack_from("<H", t, 84)[0] == 600 and struct.unpack_from("<H", t, 102)[0] == 350
    driver.relax()
    assert wait_until(lambda: not any(fake.torque(i) for i in range(16)))


def test_leap_fallback_and_missing_ids(rig):
    driver, _ = rig("leap", fast_sync=False)
    driver.connect()
    assert driver.info.identity["read"] == "sync-read"
    assert driver.read_state().q.shape == (16,)
    cfg, spec = load_hand("leap")
    fake = fake_for(cfg, ids=[i for i in range(16) if i not in (3, 9)]).start()
    try:
        with pytest.raises(IdentityError) as info:
            make_driver(cfg, spec, fake.port).connect()
        assert "ID(s) [3, 9]" in info.value.message and fake.port in info.value.message
    finally:
        fake.stop()


@pytest.mark.parametrize("hand", ["revo2", "leap"])
@pytest.mark.parametrize("fault,error", [("no_answer", BusTimeout), ("crc", BusCrcError),
                                         ("exception", DeviceFault), ("disconnect", Disconnected)])
def test_fault_switches_raise_the_right_error(rig, hand, fault, error):
    driver, fake = rig(hand)
    driver.connect()
    fake.fault = fault
    with pytest.raises(error) as info:
        driver.read_state()
    assert info.value.hint
    fake.fault = None if fault != "disconnect" else "disconnect"


def test_stale_fault_freezes_the_frame(rig):
    driver, fake = rig("inspire")
    driver.connect()
    driver.enable()
    frames = {driver.read_state().fingerprint for _ in range(3)}
    assert len(frames) > 1  # live sensor noise
    fake.fault = "stale"
    driver.write_targets(np.full(6, 0.5))
    assert len({driver.read_state().fingerprint for _ in range(4)}) == 1


def test_port_errors():
    cfg, spec = load_hand("revo2")
    with pytest.raises(HardwareError, match="no such serial port"):
        make_driver(cfg, spec, "/dev/does-not-exist-dgz").connect()
    fake = fake_for(cfg).start()
    try:
        first = make_driver(cfg, spec, fake.port)
        first.connect()
        with pytest.raises(HardwareError, match="in use by another program"):
            make_driver(cfg, spec, fake.port).connect()
        first.close()
    finally:
        fake.stop()
