"""Hand and arm files are untrusted input: every number is finite and bounded (issue 10, item 5).

Each bad file must fail at load with one line that names the file and the field, through the loader and
through ``dgz deploy`` (exit != 0, no traceback).
"""

from __future__ import annotations

import pytest
import yaml

from dgz_cli.hw.arm_config import load_arm_config, shipped_arm_configs
from dgz_cli.hw.config import hand_config_path, load_hand_config
from dgz_cli.hw.errors import ConfigError, IdentityError
from test_bad_inputs import _describe, assert_no_traceback, dgz


def _hand(name: str) -> dict:
    return yaml.safe_load(hand_config_path(name).read_text())


def _arm() -> dict:
    from dgz_cli.hw.arm_config import ARMS_DIR

    return yaml.safe_load((ARMS_DIR / f"{shipped_arm_configs()[0]}.yaml").read_text())


def _set(path: str, value):
    def mutate(d: dict) -> dict:
        keys = path.split(".")
        cur = d
        for k in keys[:-1]:
            cur = cur[int(k)] if isinstance(cur, list) else cur.setdefault(k, {})
        last = keys[-1]
        if isinstance(cur, list):
            cur[int(last)] = value
        else:
            cur[last] = value
        return d
    return mutate


def _start_pose(joint_value):
    def mutate(d: dict) -> dict:
        d["start_pose"] = {d["channels"][0]["joint"]: joint_value}
        return d
    return mutate


NAN, INF = float("nan"), float("inf")

HAND_CASES = [
    ("leap", "rad_per_unit", _set("rad_per_unit", 1e300)),
    ("leap", "rad_per_unit", _set("rad_per_unit", INF)),
    ("leap", "rad_per_unit", _set("rad_per_unit", NAN)),
    ("leap", "rad_per_unit", _set("rad_per_unit", 0.0)),
    ("leap", "channels.0.offset", _set("channels.0.offset", NAN)),
    ("leap", "channels.0.offset", _set("channels.0.offset", INF)),
    ("leap", "channels.0.offset", _set("channels.0.offset", 1e9)),
    ("leap", "start_pose", _start_pose(NAN)),
    ("leap", "start_pose", _start_pose(-INF)),
    ("leap", "start_pose", _start_pose(100.0)),
    ("leap", "channels", _set("channels.0.native", [0, 2 ** 40])),
    ("leap", "dynamixel.goal_current", _set("dynamixel.goal_current", 10 ** 9)),
    ("leap", "dynamixel.p_gain", _set("dynamixel.p_gain", -1)),
    ("leap", "port.timeout", _set("port.timeout", NAN)),
    ("leap", "port.baudrate", _set("port.baudrate", 10 ** 12)),
    ("inspire", "channels", _set("channels.0.native", [0, 70000])),
    ("inspire", "channels", _set("channels.0.native", [-5, 1000])),
    ("inspire", "inspire.force", _set("inspire.force", 5000)),
    ("revo2", "revo2.speed", _set("revo2.speed", NAN)),
    ("revo2", "channels.0.offset", _set("channels.0.offset", -INF)),
]


@pytest.mark.parametrize("hand, field, mutate", HAND_CASES,
                         ids=[f"{h}-{f}-{i}" for i, (h, f, _) in enumerate(HAND_CASES)])
def test_hand_file_numbers_are_checked(hand, field, mutate, tmp_path):
    bad = tmp_path / "bad_hand.yaml"
    bad.write_text(yaml.safe_dump(mutate(_hand(hand)), sort_keys=False))
    with pytest.raises(ConfigError) as info:
        load_hand_config(str(bad))
    msg = info.value.message
    assert "\n" not in msg and str(bad) in msg and f"field '{field}" in msg, msg


def test_shipped_hand_files_still_load():
    for hand in ("leap", "inspire", "revo2"):
        load_hand_config(hand)


@pytest.mark.parametrize("field, mutate", [
    ("workspace.x", _set("workspace.x", [NAN, 0.5])),
    ("workspace.z", _set("workspace.z", [0.0, INF])),
    ("workspace.y", _set("workspace.y", [-1e9, 0.4])),
    ("mount.xyz", _set("mount.xyz", [0.0, NAN, 0.0])),
    ("mount.rpy_deg", _set("mount.rpy_deg", [0.0, 0.0, 1e6])),
    ("max_step_m", _set("max_step_m", NAN)),
    ("enable_timeout_s", _set("enable_timeout_s", INF)),
    ("ctrl_mode", _set("ctrl_mode", 10 ** 6)),
    ("sdk_class", _set("sdk_class", "os")),
    ("can_port", _set("can_port", "can0; rm -rf /")),
])
def test_arm_file_numbers_are_checked(field, mutate, tmp_path):
    bad = tmp_path / "bad_arm.yaml"
    bad.write_text(yaml.safe_dump(mutate(_arm()), sort_keys=False))
    with pytest.raises(ConfigError) as info:
        load_arm_config(str(bad))
    msg = info.value.message
    assert "\n" not in msg and str(bad) in msg and f"field '{field}" in msg, msg


def test_shipped_arm_files_still_load():
    for arm in shipped_arm_configs():
        load_arm_config(arm)


@pytest.mark.parametrize("mutate, field", [(_set("rad_per_unit", 1e300), "rad_per_unit"),
                                           (_start_pose(NAN), "start_pose")])
def test_deploy_refuses_bad_hand_file(mutate, field, tmp_path):
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(mutate(_hand("leap")), sort_keys=False))
    r = dgz(tmp_path, "deploy", "--hand", "bad.yaml", "--fake", "--dry-run", "--policy", "close", "--yes")
    assert_no_traceback(r)
    assert r.code != 0, _describe(r)
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "bad.yaml" in lines[0] and field in lines[0], _describe(r)


def test_revo2_device_limits_are_checked():
    """Limits read from the device (±32768°) are refused at connect, naming the port and the finger."""
    from dgz_cli.hw.factory import load_hand, make_driver
    from dgz_cli.hw.fakes import fake_for

    cfg, spec = load_hand("revo2")
    for lo, hi in ((-32768, 32767), (0, 720), (50, 10)):
        fake = fake_for(cfg, min_deg=[0, lo, 0, 0, 0, 0], max_deg=[59, hi, 81, 81, 81, 81]).start()
        driver = make_driver(cfg, spec, fake.port)
        try:
            with pytest.raises(IdentityError) as info:
                driver.connect()
            assert fake.port in info.value.message and "thumb_aux" in info.value.message, info.value.message
        finally:
            driver.close()
            fake.stop()
