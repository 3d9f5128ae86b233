"""Safety filter, M_h mapping, Kalman filter, rate loop and policy interface: hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from dgz_cli.runtime.filters import KalmanCV
from dgz_cli.runtime.mapping import start_pose
from dgz_cli.runtime.policy import ClosePolicy, load_policy
from dgz_cli.runtime.types import check_privileged
from dgz_cli.runtime.rate import RateLoop
from dgz_cli.runtime.safety import SafetyConfig, SafetyFilter, UnsafeAction
from dgz_cli.spec.contract import ControlContract, EpisodeProtocol
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import load_spec

SPEC = load_spec("hand_specs/dgz_tri/spec.yaml")
NODES = [n.id for n in SPEC.nodes]
JOINTS = [j.joint for j in SPEC.joints]


def action(wrist=(0, 0, 0, 0, 0, 0), **alpha) -> np.ndarray:
    """alpha: node=(flex, abd, rot)."""
    a = np.zeros((len(NODES), 3))
    for node, values in alpha.items():
        a[NODES.index(node)] = values
    return np.concatenate([np.asarray(wrist, dtype=float), a.reshape(-1)])


def _filter(device_limits=None, cfg=SafetyConfig(), contract=ControlContract()) -> SafetyFilter:
    return SafetyFilter(SPEC, device_limits, contract, cfg)


def test_mh_mapping_uses_spec_orders_and_signs():
    """Normalized actions × the contract's scales (0.015 rad fingers), through M_h's node, primitive and sign."""
    f = _filter()
    f.reset([(j.lower + j.upper) / 2 for j in SPEC.joints])  # mid-range: no limit clips the change
    dq = f.step(action(middle_proximal=(2 / 3, 2 / 15, 0.0), thumb_proximal=(0.0, 0.0, 1 / 3))).dq
    expected = dict.fromkeys(JOINTS, 0.0)
    expected.update(index_mcp=0.01, index_abd=-0.002, thumb_rot=-0.005)  # ABD and ROT rows have sign −1
    assert dq == pytest.approx([expected[j] for j in JOINTS])


def test_clip_scale_map_integrate_on_target():
    f = _filter()
    f.reset(np.zeros(len(JOINTS)))
    cmd = f.step(action((2.0, -0.5, 0.3, 0, 0, 0), middle_proximal=(5.0, 0.4, 0.0)))
    assert cmd.wrist == pytest.approx([0.01, -0.005, 0.003, 0, 0, 0])  # clipped to [-1, 1], × 0.01
    t = dict(zip(JOINTS, cmd.target))
    assert t["index_mcp"] == pytest.approx(0.015) and t["index_abd"] == pytest.approx(-0.006)
    assert cmd.limited and cmd.action.max() == 1.0
    # integrates on the previous *target*: the measured position never enters
    cmd = f.step(action(middle_proximal=(1.0, 0.0, 0.0)))
    assert dict(zip(JOINTS, cmd.target))["index_mcp"] == pytest.approx(0.030) and not cmd.limited


def test_joint_limits_and_narrower_device_limits():
    lo = np.array([j.lower for j in SPEC.joints])
    hi = np.array([j.upper for j in SPEC.joints])
    dev_hi = hi.copy()
    dev_hi[JOINTS.index("index_mcp")] = 1.0
    f = _filter((lo - 1, dev_hi))
    f.reset(np.full(len(JOINTS), 5.0))  # reset clips too
    assert f.target[JOINTS.index("index_mcp")] == pytest.approx(1.0)
    assert f.target[JOINTS.index("index_pip")] == pytest.approx(1.6)
    f.reset(lo)
    cmd = f.step(action(middle_proximal=(-1.0, 0, 0)))
    assert cmd.target[JOINTS.index("index_mcp")] == pytest.approx(-0.1) and cmd.limited
    with pytest.raises(DgzError, match="do not overlap"):
        _filter((lo + 10, hi + 20))


def test_per_step_cap():
    f = _filter(cfg=SafetyConfig(max_joint_step=0.01))
    f.reset(np.zeros(len(JOINTS)))
    cmd = f.step(action(middle_proximal=(1.0, 0, 0)))
    assert dict(zip(JOINTS, cmd.target))["index_mcp"] == pytest.approx(0.01) and cmd.limited
    fast = ControlContract(episode=EpisodeProtocol(control_hz=1000.0, physics_dt=0.001))
    f2 = _filter(contract=fast)  # velocity 3 rad/s · 1 ms = 0.003 rad per step
    f2.reset(np.zeros(len(JOINTS)))
    assert dict(zip(JOINTS, f2.step(action(middle_proximal=(1.0, 0, 0))).target))["index_mcp"] == pytest.approx(0.003)


def test_the_cap_never_binds_on_shipped_hands_at_contract_scales():
    """So the runtime's targets equal the simulator's (which has no cap)."""
    from dgz_cli.spec.catalog import resolve_spec, shipped_hands

    c = ControlContract()
    for hand in shipped_hands():
        spec = load_spec(resolve_spec(hand))
        caps = [min(SafetyConfig().max_joint_step, j.velocity / c.episode.control_hz) if j.velocity > 0
                else SafetyConfig().max_joint_step for j in spec.joints]
        assert min(caps) >= c.action.finger_scale, hand


def test_rejects_nan_and_wrong_size():
    f = _filter()
    f.reset(np.zeros(len(JOINTS)))
    bad = action()
    bad[10] = np.nan
    with pytest.raises(UnsafeAction, match="non-finite action \\(index 10"):
        f.step(bad)
    with pytest.raises(UnsafeAction, match="expected 42"):
        f.step(np.zeros(7))
    assert np.all(f.target == 0)  # a refused action changes nothing


def test_ramp_step():
    f = _filter()
    f.reset(np.zeros(len(JOINTS)))
    goal = np.full(len(JOINTS), 0.05)
    assert np.allclose(f.approach(goal, 0.02), 0.02) and np.allclose(f.approach(goal, 0.02), 0.04)
    assert np.allclose(f.approach(goal, 0.02), 0.05)


def test_start_pose():
    q = start_pose(SPEC, {"thumb_mcp": 0.3})
    assert q[JOINTS.index("thumb_mcp")] == 0.3 and q[JOINTS.index("index_mcp")] == 0.0
    with pytest.raises(DgzError, match="not in spec"):
        start_pose(SPEC, {"nope": 1.0})


def test_kalman_hand_computed():
    # dt = 1, q = 0, r = 1, P0 = I, x0 = 0. Step 1, z = 3: P⁻ = [[2,1],[1,1]], K = [2/3, 1/3] → x = [2, 1],
    # P = [[2/3,1/3],[1/3,2/3]]. Step 2, z = 3: x⁻ = [3, 1], P⁻ = [[2,1],[1,2/3]], K = [2/3, 1/3],
    # innovation 0 → x = [3, 1].
    kf = KalmanCV(dim=1, dt=1.0, q=0.0, r=1.0, p0=1.0)
    assert kf.update([3.0]) == pytest.approx([2.0]) and kf.velocity == pytest.approx([1.0])
    assert kf.P[0] == pytest.approx(np.array([[2 / 3, 1 / 3], [1 / 3, 2 / 3]]))
    assert kf.update([3.0]) == pytest.approx([3.0]) and kf.velocity == pytest.approx([1.0])


def test_kalman_reduces_jitter_per_axis():
    rng = np.random.default_rng(1)
    kf = KalmanCV()  # wrist defaults: 6 axes at 20 Hz
    raw = 0.005 + rng.normal(0, 0.003, size=(200, 6))
    raw[:, 3:] = 0.0
    out = np.array([kf.update(z) for z in raw])
    assert np.all(out[100:, :3].std(axis=0) < 0.5 * raw[100:, :3].std(axis=0))
    assert np.allclose(out[100:, :3].mean(axis=0), 0.005, atol=0.001) and np.allclose(out[:, 3:], 0.0)


def test_rate_loop_absolute_deadlines_with_fake_clock():
    now = [0.0]
    loop = RateLoop(20.0, clock=lambda: now[0], sleep=lambda s: now.__setitem__(0, now[0] + s))
    now[0] += 0.01
    assert loop.wait() < 0 and now[0] == pytest.approx(0.05)
    now[0] += 0.12  # a slow step: due at 0.10, ends at 0.17 → overrun, slots 0.10 and 0.15 skipped
    assert loop.wait() == pytest.approx(0.07)
    assert now[0] == pytest.approx(0.20) and loop.overruns == 1 and loop.consecutive == 1
    now[0] += 0.02
    loop.wait()
    assert now[0] == pytest.approx(0.25) and loop.consecutive == 0
    assert loop.periods == pytest.approx([0.05, 0.15, 0.05])


def test_close_policy_closes_then_holds():
    p = ClosePolicy(SPEC, flex=0.5, close_steps=3)
    a = [p.act(None) for _ in range(4)]
    flex_active = np.array([SPEC.activation_mask[n][0] for n in NODES], dtype=bool)
    assert np.all(a[0][:6] == 0) and np.all(a[0][6::3][flex_active] == 0.5) and np.all(a[0][6::3][~flex_active] == 0)
    assert np.all(a[0][7::3] == 0) and np.all(a[3] == 0)


class Teacher:
    privileged_inputs = {"contact", "force"}

    def act(self, obs):
        return np.zeros(42)


def make_teacher(spec):
    return Teacher()


def test_privileged_policies_are_refused():
    with pytest.raises(DgzError, match="privileged inputs \\(contact, force\\)") as info:
        check_privileged(Teacher(), "teacher")
    assert "student policy" in info.value.hint
    check_privileged(Teacher(), "teacher", allow_privileged=True)
    with pytest.raises(DgzError, match="privileged"):
        load_policy(f"{__name__}:make_teacher", SPEC)
    assert isinstance(load_policy(f"{__name__}:make_teacher", SPEC, allow_privileged=True), Teacher)
    with pytest.raises(DgzError, match="unknown policy"):
        load_policy("magcn", SPEC)
