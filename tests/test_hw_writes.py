"""No value outside the joint limits reaches a device, from any code path (issue 10, item 2).

Every fake records every write instruction; these tests drive each hand through connect, enable, the
start-pose ramp, policy commands, hold/relax/torque-off and the runtime's exit, with healthy feedback and
with position registers corrupted to 0x7FFFFFFF (Dynamixel) / 65535 (Modbus) from the start, from the
middle of a run, or on one channel, and assert that every goal value written lies inside the narrower of
the spec's and the device's joint range. A corrupt reading must stop the run as a fault naming the joint.
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from dgz_cli.hw.errors import HardwareError, ImplausibleReading
from dgz_cli.hw.factory import load_hand, make_driver
from dgz_cli.hw.fakes import fake_for
from dgz_cli.runtime.loop import RunConfig, Runner
from dgz_cli.runtime.mapping import start_pose

try:  # the runtime's scripted closing policy (renamed along the control contract)
    from dgz_cli.runtime.policy import ClosePolicy as ScriptedClosePolicy
except ImportError:  # pragma: no cover
    from dgz_cli.runtime.policy import ScriptedClosePolicy

HANDS = ["leap", "inspire", "revo2"]
CORRUPT = {"leap": 0x7FFFFFFF, "inspire": 65535, "revo2": 65535}
GOAL_POSITION = 116  # Dynamixel
ANGLE_SET = 1486  # Inspire
POS_TIME, POS_SPEED, POS_PERCENT = 1010, 1022, 1070  # Revo2
RATE = 200.0


def run_config(on_exit: str, grasp_steps: int = 15, lift_steps: int = 3) -> RunConfig:
    """A short run at RATE Hz (through the control contract where the runtime has one)."""
    try:
        from dgz_cli.spec.contract import ControlContract, EpisodeProtocol
    except ImportError:  # pragma: no cover
        return RunConfig(rate_hz=RATE, grasp_steps=grasp_steps, lift_steps=lift_steps, on_exit=on_exit)
    episode = EpisodeProtocol(control_hz=RATE, grasp_steps=grasp_steps, lift_steps=lift_steps, hold_s=0.0)
    return RunConfig(contract=ControlContract(episode=episode), on_exit=on_exit)


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


def goal_writes(hand: str, fake) -> list[tuple[int, int]]:
    """(channel in device order, native goal value) of every goal-position value written to the fake."""
    out = []
    if hand == "leap":
        for dxl_id, addr, data in fake.writes:
            if addr < GOAL_POSITION + 4 and addr + len(data) > GOAL_POSITION:
                assert addr == GOAL_POSITION and len(data) == 4, f"partial goal write {addr} {data!r}"
                out.append((fake.order.index(dxl_id), struct.unpack("<i", data)[0]))
        return out
    for addr, values in fake.writes:
        for j, v in enumerate(values):
            reg = addr + j
            if hand == "inspire" and ANGLE_SET <= reg < ANGLE_SET + 6:
                out.append((reg - ANGLE_SET, v))
            if hand == "revo2":
                assert not POS_PERCENT <= reg < POS_PERCENT + 6, "percent set-points are never used"
                for base in (POS_TIME, POS_SPEED):
                    if base <= reg < base + 12:
                        if (reg - base) % 2 == 0:
                            out.append(((reg - base) // 2, v))
                        else:
                            assert 0 <= v <= 1000, f"speed/time word {v} out of range"
    return out


def assert_goals_in_limits(hand: str, driver, fake, expect_some: bool = True) -> int:
    spec_lo = np.array([j.lower for j in driver.spec.joints])
    spec_hi = np.array([j.upper for j in driver.spec.joints])
    dev_lo, dev_hi = driver.limits()
    lo, hi = np.maximum(spec_lo, dev_lo), np.minimum(spec_hi, dev_hi)
    m = driver.mapper
    mid = [int((a + b) // 2) for a, b in (c.native for c in driver.cfg.channels)]
    writes = goal_writes(hand, fake)
    for ch, v in writes:
        native = list(mid)
        native[ch] = v
        k = int(np.flatnonzero(m.perm == ch)[0])
        q = m.to_rad(native)[k]
        assert lo[k] - 1e-9 <= q <= hi[k] + 1e-9, (
            f"{hand}: goal {v} on channel {ch} ({driver.joint_names[k]}) = {q:.6g} rad, outside "
            f"[{lo[k]:.6g}, {hi[k]:.6g}]")
        nlo, nhi = driver.cfg.channels[ch].native
        assert nlo <= v <= nhi
    if expect_some:
        assert writes, "no goal was written at all: the test exercised nothing"
    return len(writes)


# --------------------------------------------------------------------------------------------
# the whole runtime, healthy and corrupted
# --------------------------------------------------------------------------------------------

class CorruptAfter(ScriptedClosePolicy):
    """The scripted closing policy that corrupts the fake's position registers after ``after`` steps."""

    def __init__(self, spec, fake, after: int, value: int, channels=None) -> None:
        super().__init__(spec)
        self.fake, self.after, self.value, self.channels, self.k = fake, after, value, channels, 0

    def act(self, obs):
        self.k += 1
        if self.k == self.after:
            self.fake.corrupt_channels = self.channels
            self.fake.corrupt_position = self.value
        return super().act(obs)


@pytest.mark.parametrize("on_exit", ["hold", "relax"])
@pytest.mark.parametrize("hand", HANDS)
def test_full_run_writes_only_goals_inside_the_limits(rig, hand, on_exit):
    driver, fake = rig(hand)
    driver.connect()
    res = Runner(driver, driver.spec, ScriptedClosePolicy(driver.spec),
                 run_config(on_exit)).run(start_pose(driver.spec))
    assert res.ok, res.reason
    assert res.exit_action == on_exit
    assert_goals_in_limits(hand, driver, fake)


@pytest.mark.parametrize("channels", [None, {3}], ids=["all-channels", "one-channel"])
@pytest.mark.parametrize("when", ["at-connect", "mid-run"])
@pytest.mark.parametrize("on_exit", ["hold", "relax"])
@pytest.mark.parametrize("hand", HANDS)
def test_corrupt_reading_stops_the_run_and_nothing_out_of_range_is_written(rig, hand, on_exit, when, channels):
    driver, fake = rig(hand)
    driver.connect()
    value = CORRUPT[hand]
    if when == "at-connect":
        fake.corrupt_channels, fake.corrupt_position = channels, value
        policy = ScriptedClosePolicy(driver.spec)
    else:
        policy = CorruptAfter(driver.spec, fake, after=5, value=value, channels=channels)
    res = Runner(driver, driver.spec, policy,
                 run_config(on_exit)).run(start_pose(driver.spec))
    assert not res.ok and res.exit_code != 0
    assert "outside its range" in res.reason and "joint '" in res.reason, res.reason
    if channels is not None:
        k = int(np.flatnonzero(driver.mapper.perm == 3)[0])
        assert f"joint '{driver.joint_names[k]}'" in res.reason, res.reason
    assert res.hint
    assert_goals_in_limits(hand, driver, fake, expect_some=(when == "mid-run"))


# --------------------------------------------------------------------------------------------
# each driver call on its own
# --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("hand", HANDS)
def test_driver_calls_with_corrupt_readings(rig, hand):
    driver, fake = rig(hand)
    driver.connect()
    fake.corrupt_position = CORRUPT[hand]
    with pytest.raises(ImplausibleReading) as info:
        driver.read_state()
    assert driver.port in info.value.message and "joint '" in info.value.message and info.value.hint
    n_before = len(goal_writes(hand, fake))
    if hand == "leap":
        with pytest.raises(ImplausibleReading):
            driver.enable()  # refuses before it writes anything
        assert fake.writes == []
    else:
        driver.enable()
    with pytest.raises(ImplausibleReading):
        driver.hold()
    assert len(goal_writes(hand, fake)) == n_before, "hold() wrote a goal from a corrupt reading"
    driver.torque_off()
    driver.relax()  # the open pose, clipped: needs no reading
    assert_goals_in_limits(hand, driver, fake, expect_some=hand != "leap")


@pytest.mark.parametrize("hand", HANDS)
def test_out_of_range_and_non_finite_targets(rig, hand):
    driver, fake = rig(hand)
    driver.connect()
    driver.enable()
    n = len(driver.joint_names)
    for q in (np.full(n, 1e6), np.full(n, -1e6), np.full(n, 1e300), np.linspace(-50, 50, n)):
        driver.write_targets(q)
    driver.hold()
    driver.relax()
    assert assert_goals_in_limits(hand, driver, fake) >= 4 * n
    for bad in (np.full(n, np.nan), np.full(n, np.inf), np.zeros(n + 1)):
        before = len(goal_writes(hand, fake))
        with pytest.raises(HardwareError, match="finite"):
            driver.write_targets(bad)
        assert len(goal_writes(hand, fake)) == before


@pytest.mark.parametrize("hand", HANDS)
def test_corrupt_reading_on_the_low_side_is_refused(rig, hand):
    """0x80000000 (most negative int32) on Dynamixel; on the Modbus hands 65535 read as signed is -1 → 0 is
    plausible, so a value far below the range is checked with the Dynamixel only."""
    driver, fake = rig(hand)
    driver.connect()
    if hand != "leap":
        pytest.skip("unsigned 0..1000 registers cannot read below the range")
    fake.corrupt_position = 0x80000000
    with pytest.raises(ImplausibleReading, match="reads -"):
        driver.read_state()
