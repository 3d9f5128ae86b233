"""Deploy runtime faults from the device side: a joint that does not follow its target, a NaN reading."""

from __future__ import annotations

import numpy as np
import pytest

from dgz_cli.hw.driver import DeviceInfo, HandDriver, HandState
from dgz_cli.runtime.loop import RunConfig, Runner
from dgz_cli.runtime.policy import ClosePolicy
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import ControlContract, EpisodeProtocol
from dgz_cli.spec.io import load_spec

CONTRACT = ControlContract(episode=EpisodeProtocol(control_hz=200.0, grasp_steps=40, lift_steps=2, hold_s=0.0))


class MemoryHand(HandDriver):
    """An in-memory hand: follows its targets, except joints listed in ``stuck`` (they stay where they are),
    and reads ``first`` on the first read when given."""

    protocol = "memory"

    def __init__(self, spec, stuck=(), first=None) -> None:
        super().__init__(spec, "mem0")
        self.q = spec.rest_pose().astype(float)
        self.stuck, self.first, self.reads, self.writes = set(stuck), first, 0, []
        lo = np.array([j.lower for j in spec.joints]); hi = np.array([j.upper for j in spec.joints])
        self._limits = (lo, hi)

    def connect(self) -> DeviceInfo:
        self.connected = True
        self.info = DeviceInfo(self.port, self.protocol, {"model": "memory"})
        return self.info

    def enable(self) -> None:
        pass

    def read_state(self) -> HandState:
        self.reads += 1
        q = self.q.copy()
        if self.reads == 1 and self.first is not None:
            q = np.asarray(self.first, dtype=float)
        return HandState(q=q, effort=np.zeros_like(q), effort_kind="current_mA", stamp=0.0)

    def write_targets(self, q) -> None:
        q = np.asarray(q, dtype=float)
        self.writes.append(q.copy())
        for i, name in enumerate(self.joint_names):
            if name not in self.stuck:
                self.q[i] = q[i]

    def limits(self):
        return self._limits

    def relax(self) -> None:
        pass

    def torque_off(self) -> None:
        pass

    def close(self) -> None:
        self.connected = False


@pytest.fixture(scope="module")
def spec():
    return load_spec(resolve_spec("dgz_tri"))


def _run(driver, spec, **cfg):
    with driver:
        return Runner(driver, spec, ClosePolicy(spec, CONTRACT), RunConfig(contract=CONTRACT, **cfg),
                      sleep=lambda s: None).run()


def test_a_following_hand_completes(spec):
    res = _run(MemoryHand(spec), spec)
    assert res.ok, res.reason


def _closing_joint(spec) -> str:
    """The joint the close policy moves the most."""
    d = MemoryHand(spec)
    _run(d, spec)
    return spec.joints[int(np.argmax(np.abs(d.q - spec.rest_pose())))].joint


def test_a_stuck_joint_is_a_tracking_fault_naming_it(spec):
    joint = _closing_joint(spec)
    res = _run(MemoryHand(spec, stuck={joint}), spec, max_tracking_error=0.05, tracking_steps=3)
    assert not res.ok and res.exit_code != 0
    assert f"joint '{joint}' does not follow its target" in res.reason, res.reason
    assert "bug in the policy" not in res.reason + res.hint
    assert res.exit_action != "none"


class ObjectHand(MemoryHand):
    """A hand whose joint ``held`` follows its targets until it has moved ``travel`` rad from its first reading,
    then stops there, as a finger closed onto an object does."""

    def __init__(self, spec, held: str, travel: float) -> None:
        super().__init__(spec)
        self.held_index = [r.joint for r in spec.joints].index(held)
        self.start, self.travel = float(self.q[self.held_index]), travel

    def write_targets(self, q) -> None:
        super().write_targets(q)
        i = self.held_index
        self.q[i] = self.start + float(np.clip(self.q[i] - self.start, -self.travel, self.travel))


def test_a_finger_held_by_the_object_is_not_a_tracking_fault(spec):
    """The joint moves 0.2 rad and is then held while its target runs on (the grasp): with the stuck-joint test's
    tight threshold it leads by far more than 0.05 rad for more than 3 reads, and the run still completes."""
    joint = _closing_joint(spec)
    driver = ObjectHand(spec, joint, travel=0.2)
    res = _run(driver, spec, max_tracking_error=0.05, tracking_steps=3)
    assert res.ok, res.reason
    i = driver.held_index
    assert max(abs(w[i] - driver.q[i]) for w in driver.writes) > 0.2  # the target did lead the held joint


def test_a_joint_that_the_ramp_moved_and_that_then_jams_is_a_tracking_fault(spec):
    """Travel counts from the episode's start: the ramp moves the joint 0.3 rad to the start pose, where it jams
    while the policy closes on; that is a fault, not a finger held by the object."""
    joint = _closing_joint(spec)
    i = [r.joint for r in spec.joints].index(joint)
    probe = MemoryHand(spec)
    _run(probe, spec)
    direction = float(np.sign(probe.q[i] - spec.rest_pose()[i]))
    start = spec.rest_pose().astype(float)
    travel = min(0.3, 0.5 * abs(probe.q[i] - start[i]))
    start[i] += direction * travel
    driver = ObjectHand(spec, joint, travel=travel)  # stops where the ramp leaves it: jammed at the start pose
    with driver:
        res = Runner(driver, spec, ClosePolicy(spec, CONTRACT), RunConfig(contract=CONTRACT, max_tracking_error=0.05,
                     tracking_steps=3), sleep=lambda s: None).run(start_pose=start)
    assert res.ramp_steps > 1 and not res.ok
    assert joint in res.reason and "does not follow" in res.reason, res.reason


def test_default_threshold_tolerates_a_lagging_joint(spec):
    """The default is generous: a joint that lags (is stuck) but stays within 1 rad is not a fault."""
    joint = _closing_joint(spec)
    res = _run(MemoryHand(spec, stuck={joint}), spec)
    assert res.ok, res.reason


@pytest.mark.parametrize("value", [float("nan"), float("inf"), float("-inf")])
def test_a_non_finite_first_reading_is_not_blamed_on_the_policy(spec, value):
    first = spec.rest_pose().astype(float)
    first[1] = value
    driver = MemoryHand(spec, first=first)
    res = _run(driver, spec)
    assert not res.ok
    assert f"joint '{spec.joints[1].joint}' reads" in res.reason, res.reason
    assert "bug in the policy" not in res.reason + res.hint
    assert all(np.all(np.isfinite(w)) for w in driver.writes)
