"""Per-arm facts as data: ``dgz_cli/hw/arms/<arm>.yaml`` validated by a frozen pydantic model.

An arm file holds the bus (CAN port), the SDK class, the motion mode and speed, the workspace box and
step limits the wrist target is clipped to, and how the hand is mounted on the flange. Lengths in m,
angles in degrees unless a field says rad.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from dgz_cli.hw.config import load_yaml_model
from dgz_cli.hw.errors import ConfigError

ARMS_DIR = Path(__file__).resolve().parent / "arms"


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


Metres = Annotated[float, Field(ge=-5.0, le=5.0, allow_inf_nan=False)]        # arm reach: a few metres at most
MountMetres = Annotated[float, Field(ge=-1.0, le=1.0, allow_inf_nan=False)]   # hand root from the flange
Degrees = Annotated[float, Field(ge=-360.0, le=360.0, allow_inf_nan=False)]


class Workspace(_Frozen):
    """Axis-aligned box (m, arm base frame) the flange target must stay in."""

    x: tuple[Metres, Metres]
    y: tuple[Metres, Metres]
    z: tuple[Metres, Metres]

    @model_validator(mode="after")
    def _ordered(self) -> "Workspace":
        for axis in ("x", "y", "z"):
            lo, hi = getattr(self, axis)
            if lo >= hi:
                raise ValueError(f"workspace.{axis} must be [min, max] with min < max")
        return self


class Mount(_Frozen):
    """The hand's root frame in the flange frame: translation (m) and fixed-axis roll/pitch/yaw (deg)."""

    xyz: tuple[MountMetres, MountMetres, MountMetres] = (0.0, 0.0, 0.0)
    rpy_deg: tuple[Degrees, Degrees, Degrees] = (0.0, 0.0, 0.0)


class ArmConfig(_Frozen):
    name: str = Field(pattern=r"^[a-z0-9][a-z0-9_\-]*$")
    sdk: Literal["piper_sdk"] = Field(description="Python package that talks to the arm")
    sdk_class: str = Field("C_PiperInterface", pattern=r"^C_Piper[A-Za-z0-9_]*$",
                           description="interface class in the SDK package")
    can_port: str = Field("can0", pattern=r"^[A-Za-z0-9_.\-]{1,15}$",
                          description="SocketCAN interface (bring it up first: ip link set can0 up ...)")
    ctrl_mode: int = Field(0x01, ge=0, le=0xFF, description="MotionCtrl_2 ctrl_mode: 0x01 = CAN command mode")
    move_mode: int = Field(0x00, ge=0, le=3, description="MotionCtrl_2 move_mode: 0x00 MOVE P (end pose)")
    speed_percent: int = Field(30, ge=1, le=100, description="MotionCtrl_2 move_spd_rate_ctrl")
    enable_timeout_s: float = Field(2.0, gt=0, le=30, description="wait this long for every motor to report enabled")
    workspace: Workspace
    max_step_m: float = Field(0.01, gt=0, le=0.05, description="flange translation per control step")
    max_step_rad: float = Field(0.02, gt=0, le=0.2, description="flange rotation per control step")
    max_rotation_deg: float = Field(45.0, gt=0, le=180, description="rotation away from the start orientation")
    mount: Mount = Mount()
    disable_on_exit: bool = Field(False, description="power the motors off at exit (the arm then falls!)")


def shipped_arm_configs() -> list[str]:
    return sorted(p.stem for p in ARMS_DIR.glob("*.yaml"))


def load_arm_config(name_or_path: str) -> ArmConfig:
    """An arm file by shipped name (``piper``) or path; one-line errors that name the file and field."""
    p = Path(name_or_path)
    if p.suffix not in (".yaml", ".yml"):
        p = ARMS_DIR / f"{name_or_path}.yaml"
    if not p.is_file():
        raise ConfigError(f"{p}: no such arm file", f"use one of: {', '.join(shipped_arm_configs())}, or a path")
    return load_yaml_model(p, ArmConfig, "docs/deploy.md (arm interface)")
