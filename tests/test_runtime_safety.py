"""Safety filter, M_h mapping, Kalman filter, rate loop and policy interface: hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from dgz_cli.runtime.filters import KalmanCV
from dgz_cli.runtime.mapping import MhMap, start_pose
from dgz_cli.runtime.policy import ScriptedClosePolicy, check_privileged, load_policy
from dgz_cli.runtime.rate import RateLoop
from dgz_cli.runtime.safety import SafetyConfig, SafetyFilter, UnsafeAction
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


def test_mh_mapping_uses_spec_orders_and_signs():
    mh = MhMap(SPEC)
    assert mh.action_dim == 6 + 3 * 12
    dq = mh.delta_q(action(middle_proximal=(0.01, 0.002, 0.0), thumb_proximal=(0.0, 0.0, 0.005))[6:])
    expected = dict.fromkeys(JOINTS, 0.0)
    expected.update(index_mcp=0.01, index_abd=-0.002, thumb_rot=-0.005)  # ABD and ROT rows have sign −1
    assert dq == pytest.approx([expected[j] for j in JOINTS])


def test_clip_map_integrate_on_target():
    f = SafetyFilter(SPEC, None, dt=0.05)
    f.reset(np.zeros(len(JOINTS)))
    cmd = f.step(action((0.02, -0.5, 0.003, 0, 0, 0), middle_proximal=(0.5, 0.004, 0.0)))
    assert cmd.wrist == pytest.approx([0.01, -0.01, 0.003, 0, 0, 0])
    t = dict(zip(JOINTS, cmd.target))
    assert t["index_mcp"] == pytest.approx(0.015) and t["index_abd"] == pytest.approx(-0.004)
    assert cmd.limited
    # integrates on the previous *target*: the measured position never enters
    cmd = f.step(action(middle_proximal=(0.5, 0.0, 0.0)))
    assert dict(zip(JOINTS, cmd.target))["index_mcp"] == pytest.approx(0.030)


def test_joint_limits_and_narrower_device_limits():
    lo = np.array([j.lower for j in SPEC.joints])
    hi = np.array([j.upper for j in SPEC.joints])
    dev_hi = hi.copy()
    dev_hi[JOINTS.index("index_mcp")] = 1.0
    f = SafetyFilter(SPEC, (lo - 1, dev_hi), dt=0.05)
    f.reset(np.full(len(JOINTS), 5.0))  # reset clips too
    assert f.target[JOINTS.index("index_mcp")] == pytest.approx(1.0)
    assert f.target[JOINTS.index("index_pip")] == pytest.approx(1.6)
    f.reset(lo)
    assert f.step(action(middle_proximal=(-0.01, 0, 0))).target[JOINTS.index("index_mcp")] == pytest.approx(-0.1)
    with pytest.raises(DgzError, match="do not overlap"):
        SafetyFilter(SPEC, (lo + 10, hi + 20), dt=0.05)


def test_per_step_cap():
    f = SafetyFilter(SPEC, None, dt=0.05, cfg=SafetyConfig(max_joint_step=0.01))
    f.reset(np.zeros(len(JOINTS)))
    cmd = f.step(action(middle_proximal=(0.015, 0, 0)))
    assert dict(zip(JOINTS, cmd.target))["index_mcp"] == pytest.approx(0.01)
    f2 = SafetyFilter(SPEC, None, dt=0.001)  # velocity 3 rad/s · 1 ms = 0.003 rad per step
    f2.reset(np.zeros(len(JOINTS)))
    assert dict(zip(JOINTS, f2.step(action(middle_proximal=(0.015, 0, 0))).target))["index_mcp"] == pytest.approx(0.003)


def test_rejects_nan_and_wrong_size():
    f = SafetyFilter(SPEC, None, dt=0.05)
    f.reset(np.zeros(len(JOINTS)))
    bad = action()
    bad[10] = np.nan
    with pytest.raises(UnsafeAction, match="non-finite action \\(index 10"):
        f.step(bad)
    with pytest.raises(UnsafeAction, match="expected 42"):
        f.step(np.zeros(7))
    assert np.all(f.target == 0)  # a refused action changes nothing


def test_ramp_step():
    f = SafetyFilter(SPEC, None, dt=0.05)
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


def test_scripted_policy_closes_then_holds():
    p = ScriptedClosePolicy(SPEC, rate=0.01, close_steps=3)
    a = [p.act(None) for _ in range(4)]
    assert np.all(a[0][:6] == 0) and np.all(a[0][6::3] == 0.01) and np.all(a[0][7::3] == 0) and np.all(a[3] == 0)


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
