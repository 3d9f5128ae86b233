"""AgileX Piper behind the arm interface, through ``piper-sdk`` (imported only when ``--arm piper`` is used).

SDK calls (units of the SDK: positions 0.001 mm, angles 0.001 deg, integers):

* connect: ``C_PiperInterface(can_port)``, ``ConnectPort()``, ``GetArmEndPoseMsgs().end_pose`` (X_axis …
  RZ_axis): the start pose, which must lie inside the workspace box. Reads only (dry runs stop here).
* enable: ``EnableArm(7)`` until ``GetArmEnableStatus()`` reports every motor enabled (timeout from the
  arm file), then ``MotionCtrl_2(ctrl_mode, move_mode, speed_percent, 0x00)``.
* each step: the wrist increment → :class:`~dgz_cli.hw.arm.WristTracker` (step cap, workspace box,
  rotation cone) → ``EndPoseCtrl(X, Y, Z, RX, RY, RZ)``.
* exit (``hold``): ``MotionCtrl_2`` again, then ``EndPoseCtrl`` at the *measured* end pose so the arm stops
  where it is, still powered. ``DisableArm(7)`` only if the arm file says ``disable_on_exit`` (a disabled
  Piper falls). ``close``: ``DisconnectPort()`` when the SDK has it.
"""

from __future__ import annotations

import importlib
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from dgz_cli.hw.arm import ArmInterface, ArmLimits, WristTracker, euler_to_matrix, matrix_to_euler
from dgz_cli.hw.arm_config import ArmConfig
from dgz_cli.hw.errors import HardwareError

M_PER_UNIT = 1e-6                  # 0.001 mm
RAD_PER_UNIT = np.pi / 180 / 1000  # 0.001 deg


class ArmError(HardwareError):
    """The arm refused, vanished or is outside its configured workspace."""


def mount_transform(cfg: ArmConfig) -> tuple[np.ndarray, np.ndarray]:
    """Hand root frame in the flange frame: rotation (3, 3), translation (3,)."""
    return euler_to_matrix(*np.radians(cfg.mount.rpy_deg)), np.array(cfg.mount.xyz, dtype=float)


def pose_to_units(p: np.ndarray, r: np.ndarray) -> tuple[int, ...]:
    """Flange pose (m, rotation matrix) → the six integers of ``EndPoseCtrl``."""
    e = matrix_to_euler(r)
    return tuple(int(round(v / M_PER_UNIT)) for v in p) + tuple(int(round(v / RAD_PER_UNIT)) for v in e)


def end_pose_units(msg: Any) -> tuple[int, ...]:
    """``GetArmEndPoseMsgs()`` → its six integers (X, Y, Z in 0.001 mm; RX, RY, RZ in 0.001 deg)."""
    e = msg.end_pose
    return tuple(int(v) for v in (e.X_axis, e.Y_axis, e.Z_axis, e.RX_axis, e.RY_axis, e.RZ_axis))


def units_to_pose(units: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Six ``EndPoseCtrl`` integers → flange position (3,) m and rotation (3, 3)."""
    u = np.array(units, dtype=float)
    return u[:3] * M_PER_UNIT, euler_to_matrix(*(u[3:] * RAD_PER_UNIT))


def import_sdk(cfg: ArmConfig) -> Callable[..., Any]:
    try:
        module = importlib.import_module(cfg.sdk)
    except ImportError:
        raise ArmError(f"--arm {cfg.name} needs the '{cfg.sdk}' package, which is not installed",
                       "pip install piper_sdk (it brings python-can), or use --arm none / --arm sim") from None
    cls = getattr(module, cfg.sdk_class, None)
    if cls is None:
        raise ArmError(f"{cfg.sdk} has no class {cfg.sdk_class}",
                       "set sdk_class in the arm file (C_PiperInterface or C_PiperInterface_V2)")
    return cls


class PiperArm(ArmInterface):
    name = "piper"
    moves = True

    def __init__(self, cfg: ArmConfig, r_palm: np.ndarray, c_palm: np.ndarray,
                 sdk_factory: Callable[..., Any] | None = None, sleep: Callable[[float], None] = time.sleep) -> None:
        """``r_palm`` (3, 3) / ``c_palm`` (3,): palm axes and centre in the hand's root frame."""
        r_m, t_m = mount_transform(cfg)
        box = np.array([cfg.workspace.x, cfg.workspace.y, cfg.workspace.z], dtype=float)
        self.limits = ArmLimits(box, cfg.max_step_m, cfg.max_step_rad, np.radians(cfg.max_rotation_deg))
        self.tracker = WristTracker(r_m @ r_palm, t_m + r_m @ c_palm, self.limits)
        self.cfg, self.sleep = cfg, sleep
        self.sdk_factory = sdk_factory or import_sdk(cfg)  # fails here, before any hardware is touched
        self.sdk: Any = None
        self.enabled = False

    def _call(self, what: str, *args: Any) -> Any:
        try:
            return getattr(self.sdk, what)(*args)
        except Exception as exc:  # the SDK raises plain exceptions on CAN errors
            raise ArmError(f"Piper on {self.cfg.can_port}: {what} failed: {' '.join(str(exc).split())}",
                           f"check the CAN adapter and `ip link show {self.cfg.can_port}`") from None

    def measured(self) -> tuple[int, ...]:
        """The measured end pose in SDK units."""
        return end_pose_units(self._call("GetArmEndPoseMsgs"))

    def connect(self) -> str:
        try:
            self.sdk = self.sdk_factory(self.cfg.can_port)
        except Exception as exc:
            raise ArmError(f"Piper: cannot open CAN port {self.cfg.can_port}: {' '.join(str(exc).split())}",
                           f"bring it up: sudo ip link set {self.cfg.can_port} up type can bitrate 1000000") from None
        self._call("ConnectPort")
        p, r = units_to_pose(self.measured())
        box = self.limits.workspace
        if np.any(p < box[:, 0]) or np.any(p > box[:, 1]):
            raise ArmError(f"Piper end pose ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is outside the workspace box "
                           f"of arm file '{self.cfg.name}'",
                           "move the arm to the pre-grasp pose first, or widen 'workspace' in the arm file")
        self.tracker.start(p, r)
        return f"Piper on {self.cfg.can_port} at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m"

    def enable(self) -> None:
        cfg = self.cfg
        deadline = time.monotonic() + cfg.enable_timeout_s
        while True:
            self._call("EnableArm", 7)
            status = self._call("GetArmEnableStatus") if hasattr(self.sdk, "GetArmEnableStatus") else [True]
            if all(status):
                break
            if time.monotonic() > deadline:
                raise ArmError(f"Piper on {cfg.can_port}: motors not enabled after {cfg.enable_timeout_s:g} s "
                               f"(status {list(status)})", "check the e-stop and the arm's power, then retry")
            self.sleep(0.05)
        self._call("MotionCtrl_2", cfg.ctrl_mode, cfg.move_mode, cfg.speed_percent, 0x00)
        self.tracker.start(*units_to_pose(self.measured()))
        self.enabled = True

    def command(self, delta: np.ndarray, frame: str = "palm", lift: float = 0.0) -> dict:
        limited = self.tracker.step(delta, frame, lift)
        units = pose_to_units(self.tracker.p, self.tracker.r)
        self._call("EndPoseCtrl", *units)
        return {"arm_target": list(units), "arm_limited": limited}

    def palm_pose(self) -> tuple[np.ndarray, np.ndarray]:
        return self.tracker.palm_pose()

    def hold(self) -> str:
        if self.sdk is None or not self.enabled:
            return "none"
        units = self.measured()  # sent back as read: no conversion round trip
        self._call("MotionCtrl_2", self.cfg.ctrl_mode, self.cfg.move_mode, self.cfg.speed_percent, 0x00)
        self._call("EndPoseCtrl", *units)
        if self.cfg.disable_on_exit:
            self._call("DisableArm", 7)
            self.enabled = False
            return "disabled"
        return "hold"

    def close(self) -> None:
        if self.sdk is not None and hasattr(self.sdk, "DisconnectPort"):
            try:
                self.sdk.DisconnectPort()
            except Exception:
                pass
        self.sdk = None
