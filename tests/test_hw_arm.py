"""The arm interface: wrist-increment math, the Piper driver against a recording fake SDK (units, limits,
enable and safe-stop sequences), the missing-SDK error, and the Piper in the control loop and `dgz deploy`."""

from __future__ import annotations

import sys
import types
from types import SimpleNamespace

import numpy as np
import pytest
from rich.console import Console

from dgz_cli.cli import deploy_cmd
from dgz_cli.hw.arm import ArmLimits, WristTracker, euler_to_matrix, matrix_to_euler, rotvec_to_matrix
from dgz_cli.hw.arm_config import load_arm_config
from dgz_cli.hw.errors import ConfigError
from dgz_cli.hw.piper import ArmError, PiperArm
from dgz_cli.spec.contract import ControlContract, EpisodeProtocol
from dgz_cli.spec.errors import DgzError

CFG = load_arm_config("piper")
START = (300_000, -20_000, 250_000, 180_000, 0, 90_000)  # 0.3 m, -0.02 m, 0.25 m; 180°, 0°, 90°


class FakePiperSdk:
    """Records every call; the end pose it reports is START until a test changes ``pose``."""

    instances: list["FakePiperSdk"] = []

    def __init__(self, can_name: str = "can0") -> None:
        self.can_name, self.calls, self.pose = can_name, [], START
        self.enable_after, self.fail = 1, None  # GetArmEnableStatus is all-True from the n-th call on
        FakePiperSdk.instances.append(self)

    def __getattr__(self, name: str):
        if name[0].isupper():
            def record(*args):
                self.calls.append((name, args))
                if self.fail == name:
                    raise OSError("CAN bus error: no ACK")
            return record
        raise AttributeError(name)

    def GetArmEndPoseMsgs(self):
        self.calls.append(("GetArmEndPoseMsgs", ()))
        keys = ("X_axis", "Y_axis", "Z_axis", "RX_axis", "RY_axis", "RZ_axis")
        return SimpleNamespace(end_pose=SimpleNamespace(**dict(zip(keys, self.pose))))

    def GetArmEnableStatus(self):
        self.calls.append(("GetArmEnableStatus", ()))
        self.enable_after -= 1
        return [self.enable_after <= 0] * 6

    def names(self) -> list[str]:
        return [c[0] for c in self.calls]


def piper(cfg=CFG, **kw) -> tuple[PiperArm, FakePiperSdk]:
    arm = PiperArm(cfg, np.eye(3), np.zeros(3), sdk_factory=FakePiperSdk, sleep=lambda s: None, **kw)
    arm.connect()
    return arm, arm.sdk


def test_rotation_helpers_round_trip():
    e = np.array([0.3, -0.4, 2.0])
    np.testing.assert_allclose(matrix_to_euler(euler_to_matrix(*e)), e, atol=1e-12)
    np.testing.assert_allclose(euler_to_matrix(0, 0, np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(rotvec_to_matrix([0, 0, np.pi / 2]), euler_to_matrix(0, 0, np.pi / 2), atol=1e-12)


def test_tracker_maps_palm_increments_and_applies_limits():
    r_fp = euler_to_matrix(0, 0, np.pi / 2)  # palm f = flange y, palm l = −flange x
    box = np.array([[-1.0, 1.0], [-1.0, 1.0], [0.0, 0.1]])
    t = WristTracker(r_fp, np.array([0.0, 0.0, 0.05]), ArmLimits(box, 0.01, 0.02, np.radians(10)))
    t.start(np.zeros(3), np.eye(3))
    assert not t.step([0.004, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(t.p, [0, 0.004, 0], atol=1e-15)                    # palm f → flange/base y
    assert t.step([0.03, 0.04, 0, 0, 0, 0])                              # |Δp| 5 cm → capped to 1 cm
    assert np.linalg.norm(t.p - [0, 0.004, 0]) == pytest.approx(0.01)
    assert t.step([0, 0, -0.01, 0, 0, 0], frame="base") and t.p[2] == 0.0  # base −z: the box floor clips it
    for _ in range(20):
        t.step([0, 0, 0, 0.02, 0, 0])                                    # the cone stops rotation at 10°
    from dgz_cli.hw.arm import matrix_angle

    assert matrix_angle(t.r) <= np.radians(10) + 1e-9
    p, r = t.palm_pose()
    np.testing.assert_allclose(r[:, 0], [1, 0, 0], atol=1e-9)            # rotated about the palm's own f axis


def test_piper_connect_enable_command_units_and_safe_stop():
    arm, sdk = piper()
    assert sdk.can_name == "can0" and sdk.names() == ["ConnectPort", "GetArmEndPoseMsgs"]  # connect only reads
    sdk.enable_after = 3
    arm.enable()
    names = sdk.names()
    assert names[2:8] == ["EnableArm", "GetArmEnableStatus"] * 3 and ("EnableArm", (7,)) in sdk.calls
    assert sdk.calls[8] == ("MotionCtrl_2", (0x01, 0x00, 30, 0x00))     # CAN mode, MOVE P, 30 % speed
    sdk.calls.clear()
    # palm = flange here (mount identity, palm axes = root axes); the flange is rotated 180° about x, 90° about z
    out = arm.command(np.array([0.005, 0.0, 0.0, 0.0, 0.0, 0.0]))       # 5 mm along the palm's f axis
    (name, units), = sdk.calls
    assert name == "EndPoseCtrl" and all(isinstance(u, int) for u in units)
    r0 = euler_to_matrix(*np.radians([180, 0, 90]))
    expect = np.array(START[:3]) + 1e6 * (r0 @ [0.005, 0, 0])             # 0.001 mm units
    np.testing.assert_allclose(units[:3], expect, atol=1)
    assert units[:3] == (300_000, -15_000, 250_000)
    np.testing.assert_allclose(euler_to_matrix(*np.radians(np.array(units[3:]) / 1000)), r0, atol=1e-5)  # 0.001°
    assert out["arm_target"] == list(units) and not out["arm_limited"]
    sdk.calls.clear()
    assert arm.command(np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.05]))["arm_limited"]  # 0.05 rad > 0.02 cap
    rz = np.radians(sdk.calls[-1][1][5] / 1000) - np.radians(90)
    assert abs(abs(rz) - 0.02) < 1e-4
    sdk.pose = (310_000, -10_000, 260_000, 180_000, 0, 90_000)          # where the arm actually is now
    sdk.calls.clear()
    assert arm.hold() == "hold"
    assert sdk.calls == [("GetArmEndPoseMsgs", ()), ("MotionCtrl_2", (0x01, 0x00, 30, 0x00)),
                         ("EndPoseCtrl", (310_000, -10_000, 260_000, 180_000, 0, 90_000))]  # stop where it is
    arm.close()
    assert sdk.names()[-1] == "DisconnectPort" and "DisableArm" not in sdk.names()  # stays powered


def test_piper_workspace_step_limit_and_disable_on_exit():
    cfg = CFG.model_copy(update={"disable_on_exit": True, "can_port": "can1"})
    arm, sdk = piper(cfg)
    assert sdk.can_name == "can1"
    arm.enable()
    for _ in range(40):  # base +z at 1 cm per step: the box top (0.55 m) stops it
        arm.command(np.array([0.0, 0.0, 0.02, 0.0, 0.0, 0.0]), frame="base")
    zs = [c[1][2] for c in sdk.calls if c[0] == "EndPoseCtrl"]
    assert np.diff(zs).max() == 10_000 and zs[-1] == 550_000
    assert arm.hold() == "disabled" and sdk.calls[-1] == ("DisableArm", (7,))


def test_piper_refuses_a_start_outside_the_workspace_and_a_dead_enable():
    class Far(FakePiperSdk):
        def __init__(self, can_name="can0"):
            super().__init__(can_name)
            self.pose = (900_000, 0, 250_000, 0, 0, 0)
    arm = PiperArm(CFG, np.eye(3), np.zeros(3), sdk_factory=Far)
    with pytest.raises(ArmError, match=r"end pose \(0.900, 0.000, 0.250\) m is outside the workspace box"):
        arm.connect()
    arm, sdk = piper(CFG.model_copy(update={"enable_timeout_s": 0.01}))
    sdk.enable_after = 10 ** 9
    with pytest.raises(ArmError, match="motors not enabled after 0.01 s") as info:
        arm.enable()
    assert "e-stop" in info.value.hint
    assert arm.hold() == "none"  # never enabled: nothing to hold, nothing sent
    sdk.fail = "EndPoseCtrl"
    arm.enabled = True
    with pytest.raises(ArmError, match="Piper on can0: EndPoseCtrl failed: CAN bus error"):
        arm.command(np.zeros(6))


def test_missing_sdk_is_one_line(monkeypatch):
    monkeypatch.setitem(sys.modules, "piper_sdk", None)  # import piper_sdk → ImportError
    with pytest.raises(ArmError, match="needs the 'piper_sdk' package, which is not installed") as info:
        PiperArm(CFG, np.eye(3), np.zeros(3)).connect()
    assert "pip install piper_sdk" in info.value.hint
    with pytest.raises(DgzError, match="not installed"):
        deploy_cmd.run("dgz_tri", "sim", "close", None, False, False, True, None, "hold", None, Console(), arm="piper")


def test_arm_files_are_validated(tmp_path):
    bad = tmp_path / "arm.yaml"
    bad.write_text("name: x\nsdk: piper_sdk\nworkspace: {x: [1, 0], y: [0, 1], z: [0, 1]}\n")
    with pytest.raises(ConfigError, match="field 'workspace': .*min < max"):
        load_arm_config(str(bad))
    bad.write_text("name: x\nsdk: piper_sdk\nworkspace: {x: [0, 1], y: [0, 1], z: [0, 1]}\nspeed: 3\n")
    with pytest.raises(ConfigError, match="unknown key 'speed'"):
        load_arm_config(str(bad))
    with pytest.raises(DgzError, match="--arm 'kinova' is not supported"):
        deploy_cmd.run("dgz_tri", "sim", "close", None, False, False, True, None, "hold", None, Console(), arm="kinova")


def test_deploy_drives_the_piper_through_the_loop(monkeypatch, tmp_path):
    FakePiperSdk.instances.clear()
    monkeypatch.setitem(sys.modules, "piper_sdk", types.SimpleNamespace(C_PiperInterface=FakePiperSdk))
    out = Console(width=200, record=True)
    contract = ControlContract(episode=EpisodeProtocol(control_hz=100.0, grasp_steps=10, lift_steps=20, hold_s=0.0,
                                                       lift_height=0.2))
    code = deploy_cmd.run("dgz_tri", "sim", "close", None, False, False, True, tmp_path / "a.jsonl", "hold", None, out,
                          arm="piper", contract=contract)
    assert code == 0, out.export_text()
    sdk, = FakePiperSdk.instances
    names = sdk.names()
    assert names[:2] == ["ConnectPort", "GetArmEndPoseMsgs"] and "MotionCtrl_2" in names
    poses = [c[1] for c in sdk.calls if c[0] == "EndPoseCtrl"]
    assert len(poses) == 10 + 20 + 1  # one per step, then the hold at exit
    lift_z = [p[2] for p in poses[10:30]]
    assert lift_z == sorted(lift_z) and lift_z[-1] - START[2] > 100_000  # Kalman-smoothed 1 cm/step lift
    assert names[-1] == "DisconnectPort" and "DisableArm" not in names
    assert "arm: hold" in out.export_text()


def test_arm_fault_stops_the_loop_safely(monkeypatch):
    from dgz_cli.hw.factory import make_sim_driver
    from dgz_cli.runtime.loop import RunConfig, Runner
    from dgz_cli.runtime.policy import ClosePolicy

    arm, sdk = piper()
    real = sdk.__getattr__("EndPoseCtrl")
    count = []

    def flaky(*args):
        count.append(1)
        if len(count) == 5:
            sdk.fail = "EndPoseCtrl"
        return real(*args)
    monkeypatch.setattr(sdk, "EndPoseCtrl", flaky, raising=False)
    with make_sim_driver("dgz_tri") as hand:
        contract = ControlContract(episode=EpisodeProtocol(control_hz=100.0))
        res = Runner(hand, hand.spec, ClosePolicy(hand.spec, contract), RunConfig(contract=contract), arm=arm).run()
    assert not res.ok and res.exit_code == 1 and "EndPoseCtrl failed" in res.reason and res.steps == 4
    assert res.exit_action == "hold" and res.arm_exit.startswith("failed")
