"""Hand files (YAML → frozen pydantic) and the channel ↔ spec-joint mapping: order, sign, offset, range."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

from dgz_cli.hw.config import HandConfig, hand_config_path, load_hand_config, shipped_hand_configs
from dgz_cli.hw.errors import ConfigError
from dgz_cli.hw.factory import load_hand
from dgz_cli.hw.fakes.revo2 import MAX_DEG, MIN_DEG
from dgz_cli.hw.jointmap import JointMapper

REVO2_LIMITS = list(zip(MIN_DEG, MAX_DEG))


def mapper(hand: str) -> tuple[JointMapper, object, object]:
    cfg, spec = load_hand(hand)
    return JointMapper(cfg, spec, REVO2_LIMITS if cfg.conversion == "device_limits" else None), cfg, spec


def test_shipped_hand_files():
    assert shipped_hand_configs() == ["inspire", "leap", "revo2"]
    for hand in shipped_hand_configs():
        m, cfg, spec = mapper(hand)
        assert sorted(m.joint_names) == sorted(c.joint for c in cfg.channels)  # every spec joint has a channel
        with pytest.raises(ValidationError):
            cfg.name = "x"  # frozen


@pytest.mark.parametrize("hand", ["leap", "inspire", "revo2"])
def test_round_trip_native_rad_native(hand):
    m, cfg, _ = mapper(hand)
    rng = np.random.default_rng(0)
    for _ in range(20):
        native = [int(rng.integers(c.native[0], c.native[1] + 1)) for c in cfg.channels]
        assert m.to_native(m.to_rad(native)) == native


@pytest.mark.parametrize("hand", ["leap", "inspire", "revo2"])
def test_closing_is_plus_flex(hand):
    """Moving every channel toward 'closed' must move each FLEX joint in its +FLEX direction (sign·Δq > 0)."""
    m, cfg, spec = mapper(hand)
    lo = [c.native[0] for c in cfg.channels]
    hi = [c.native[1] for c in cfg.channels]
    opened, closed = (lo, hi) if cfg.closing == "increasing" else (hi, lo)
    if hand == "leap":  # ticks wrap: compare around the flat pose instead of the ends of the range
        opened, closed = [2048] * 16, [2148] * 16
    dq = m.to_rad(closed) - m.to_rad(opened)
    for k, row in enumerate(spec.joints):
        if row.primitive.value == "FLEX":
            assert row.sign * dq[k] > 0, row.joint


def test_inspire_convention_and_order():
    m, cfg, spec = mapper("inspire")
    assert [c.name for c in cfg.channels] == ["little", "ring", "middle", "index", "thumb_bend", "thumb_rotation"]
    q = m.to_rad([1000, 1000, 1000, 1000, 1000, 0])  # open, thumb rotation fully to 0
    names = m.joint_names
    assert q[names.index("pinky_proximal_joint")] == 0.0
    assert q[names.index("thumb_proximal_yaw_joint")] == pytest.approx(1.308)  # upper limit of the spec
    # lower + (1000 − n)/1000·(upper − lower): n = 250 on the index → 0.75·1.47
    assert m.to_rad([1000, 1000, 1000, 250, 1000, 1000])[names.index("index_proximal_joint")] == pytest.approx(1.1025)
    assert m.to_native(q) == [1000, 1000, 1000, 1000, 1000, 0]


def test_revo2_device_limits_formula():
    m, cfg, spec = mapper("revo2")
    q = m.to_rad([500, 1000, 0, 0, 0, 250])
    names = m.joint_names
    assert q[names.index("right_thumb_proximal_joint")] == pytest.approx(math.radians(0 + 500 * 59 / 1000))
    assert q[names.index("right_thumb_metacarpal_joint")] == pytest.approx(math.radians(90))
    assert q[names.index("right_pinky_proximal_joint")] == pytest.approx(math.radians(250 * 81 / 1000))
    with pytest.raises(ConfigError, match="needs the limits read from the device"):
        JointMapper(cfg, spec, None)
    with pytest.raises(ConfigError, match="empty position limits"):
        JointMapper(cfg, spec, [(0, 0)] * 6)


def test_leap_pi_offset_and_clipping():
    m, cfg, _ = mapper("leap")
    assert np.allclose(m.to_rad([2048] * 16), 0.0)  # real flat pose (π) is sim 0
    assert m.to_rad([3072] + [2048] * 15)[0] == pytest.approx(math.pi / 2)
    assert m.to_native(np.full(16, 10.0)) == [4095] * 16  # out of range → clipped to the native range
    lo, hi = m.limits()
    assert lo[0] == pytest.approx(-math.pi) and hi[0] == pytest.approx(math.pi - 2 * math.pi / 4096)
    with pytest.raises(ValueError):
        m.to_native(np.full(16, np.nan))


def _raw(hand: str) -> dict:
    return yaml.safe_load(hand_config_path(hand).read_text())


def test_config_validation(tmp_path):
    bad = _raw("revo2")
    bad["speed"] = 3
    (tmp_path / "a.yaml").write_text(yaml.safe_dump(bad))
    with pytest.raises(ConfigError, match="unknown key 'speed'"):
        load_hand_config(str(tmp_path / "a.yaml"))
    bad = _raw("inspire")
    bad["channels"][1]["joint"] = bad["channels"][0]["joint"]
    with pytest.raises(ValueError, match="duplicate channel joint"):
        HandConfig.model_validate(bad)
    bad = _raw("leap")
    bad["channels"][0]["native"] = [10, 5]
    with pytest.raises(ValueError, match="min < max"):
        HandConfig.model_validate(bad)
    bad = _raw("revo2")
    del bad["slave_id"]
    with pytest.raises(ValueError, match="needs slave_id"):
        HandConfig.model_validate(bad)
    with pytest.raises(ConfigError, match="no hardware driver file for hand 'allegro'"):
        load_hand_config("allegro")


def test_channels_must_match_the_spec():
    cfg, spec = load_hand("inspire")
    data = cfg.model_dump()
    data["channels"][0]["joint"] = "no_such_joint"
    with pytest.raises(ConfigError, match="not in spec 'inspire'"):
        JointMapper(HandConfig.model_validate(data), spec)
    data = cfg.model_dump()
    data["channels"] = data["channels"][:5]
    with pytest.raises(ConfigError, match="have no channel"):
        JointMapper(HandConfig.model_validate(data), spec)


def test_new_hand_is_only_a_file(tmp_path):
    """A left Revo2 (slave 126) needs no code: a file with a different slave id."""
    data = _raw("revo2")
    data.update(name="revo2-left-test", slave_id=126)
    path = tmp_path / "revo2_left.yaml"
    path.write_text(yaml.safe_dump(data))
    cfg = load_hand_config(str(path))
    assert cfg.slave_id == 126 and cfg.protocol == "revo2_modbus"
