"""Per-hand facts as data: ``hand_specs/<hand>/hardware.yaml`` validated by a frozen pydantic model.

A hand whose wire protocol is already implemented needs only such a file (no code). Channels are listed
in the device's own order; each names the HandSpec joint it drives (``joints[].joint`` in hand_specs/).
Native units ↔ radians (``conversion``):

* ``linear``:        rad = sign · native · rad_per_unit + offset              (Dynamixel ticks)
* ``spec_limits``:   u = (native − lo)/(hi − lo); f = u if sign > 0 else 1 − u;
                     rad = lower + f · (upper − lower) + offset               (spec joint limits; Inspire)
* ``device_limits``: same as spec_limits with [lower, upper] = [min_deg, max_deg]·π/180 read from the
                     device at connect (never URDF limits; Revo2)
"""

from __future__ import annotations

from pathlib import Path
import math
from typing import Annotated, Literal, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, field_validator, model_validator

from dgz_cli.hw.errors import ConfigError
from dgz_cli.spec.catalog import HARDWARE_FILE, hand_dir, shipped_hands

M = TypeVar("M", bound=BaseModel)


class Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


# bounds on the numbers a hand file may hold (a typo must fail at load, not as a motion)
MAX_OFFSET_RAD = 2 * math.pi + 0.5     # a channel offset or start pose beyond a turn is a typo
Radians = Annotated[float, Field(ge=-MAX_OFFSET_RAD, le=MAX_OFFSET_RAD, allow_inf_nan=False)]
NATIVE_BOUNDS = {"dynamixel2": (-(2 ** 31) + 1, 2 ** 31 - 1), "inspire_modbus": (0, 0xFFFF),
                 "revo2_modbus": (0, 0xFFFF)}  # int32 goal position / unsigned 16-bit Modbus register


class PortSettings(Frozen):
    baudrate: int = Field(gt=0, le=20_000_000)
    bytesize: Literal[7, 8] = 8
    parity: Literal["N", "E", "O"] = "N"
    stopbits: Literal[1, 2] = 1
    timeout: float = Field(0.05, gt=0, le=2.0, description="reply timeout per read, s")


class Channel(Frozen):
    name: str = Field(description="the device's name for the channel")
    id: int | None = Field(None, ge=0, le=252, description="bus id (Dynamixel motor id); Modbus: list order")
    joint: str = Field(description="HandSpec joint this channel drives (joints[].joint)")
    sign: Literal[-1, 1] = 1
    offset: Radians = Field(0.0, description="rad, added after scaling")
    native: tuple[int, int] = Field(description="[min, max] in device units; commands are clipped to it")

    @model_validator(mode="after")
    def _range(self) -> "Channel":
        if self.native[0] >= self.native[1]:
            raise ValueError(f"native range {list(self.native)} must be [min, max] with min < max")
        return self


class DynamixelSettings(Frozen):
    operating_mode: int = Field(5, ge=0, le=16, description="11: 5 = current-based position control")
    goal_current: int = Field(350, ge=0, le=2047, description="102, mA-ish units (350 LEAP Lite, 550 Full)")
    p_gain: int = Field(600, ge=0, le=16383)
    i_gain: int = Field(0, ge=0, le=16383)
    d_gain: int = Field(200, ge=0, le=16383)
    fast_sync_read: bool = Field(True, description="try fast-sync-read (0x8A) first, fall back to sync-read")
    model_numbers: list[int] = Field(default_factory=list, description="accepted ping model numbers; [] = any")


class InspireSettings(Frozen):
    force: int = Field(500, ge=0, le=1000, description="FORCE_SET 1498 for every finger")
    speed: int = Field(500, ge=0, le=1000, description="SPEED_SET 1522 while the policy runs")
    relax_speed: int = Field(200, ge=0, le=1000, description="SPEED_SET used to open the hand on relax")


class Revo2Settings(Frozen):
    speed: int = Field(500, ge=0, le=1000, description="speed word of the 1022 [position, speed] pairs")
    relax_speed: int = Field(200, ge=0, le=1000)
    skus: list[int] = Field(default_factory=list, description="accepted SKU values at 901; [] = any")


class HandConfig(Frozen):
    name: str = Field(pattern=r"^[a-z0-9][a-z0-9_\-]*$")
    protocol: Literal["dynamixel2", "inspire_modbus", "revo2_modbus"]
    spec: str = Field(description="shipped HandSpec name (hand_specs/<spec>.yaml) or a path")
    port: PortSettings
    slave_id: int | None = Field(None, ge=1, le=247, description="Modbus slave id")
    conversion: Literal["linear", "spec_limits", "device_limits"]
    rad_per_unit: float | None = Field(None, ge=1e-7, le=0.1, description="linear conversion only (rad per device "
                                       "unit: 2π/4096 for Dynamixel ticks)")
    closing: Literal["increasing", "decreasing"] = Field(description="native direction that closes (+FLEX)")
    channels: list[Channel] = Field(min_length=1)
    start_pose: dict[str, Radians] = Field(default_factory=dict, description="joint → rad before the policy starts")
    dynamixel: DynamixelSettings | None = None
    inspire: InspireSettings | None = None
    revo2: Revo2Settings | None = None

    @field_validator("channels")
    @classmethod
    def _native_bounds(cls, channels: list[Channel], info: ValidationInfo) -> list[Channel]:
        protocol = info.data.get("protocol")
        lo, hi = NATIVE_BOUNDS.get(protocol, NATIVE_BOUNDS["dynamixel2"])
        for i, c in enumerate(channels):
            if not lo <= c.native[0] < c.native[1] <= hi:
                raise ValueError(f"channels.{i} ('{c.name}'): native range {list(c.native)} must lie within "
                                 f"[{lo}, {hi}] for protocol {protocol}")
        return channels

    @model_validator(mode="after")
    def _consistent(self) -> "HandConfig":
        for what, values in (("channel name", [c.name for c in self.channels]),
                             ("channel joint", [c.joint for c in self.channels])):
            dup = {v for v in values if values.count(v) > 1}
            if dup:
                raise ValueError(f"duplicate {what}: {sorted(dup)}")
        if self.conversion == "linear" and self.rad_per_unit is None:
            raise ValueError("conversion 'linear' needs rad_per_unit")
        if self.protocol == "dynamixel2":
            ids = [c.id for c in self.channels]
            if None in ids or len(set(ids)) != len(ids):
                raise ValueError("every dynamixel channel needs a unique id")
        elif self.slave_id is None:
            raise ValueError(f"protocol {self.protocol} needs slave_id")
        return self

    def settings(self):
        """The protocol's settings block (defaults when the file omits it)."""
        if self.protocol == "dynamixel2":
            return self.dynamixel or DynamixelSettings()
        if self.protocol == "inspire_modbus":
            return self.inspire or InspireSettings()
        return self.revo2 or Revo2Settings()


def shipped_hand_configs() -> list[str]:
    """Shipped hands that have a hardware file (``hand_specs/<hand>/hardware.yaml``)."""
    return [h for h in shipped_hands() if (hand_dir(h) / HARDWARE_FILE).is_file()]


def hand_config_path(name_or_path: str) -> Path:
    """A shipped hand name (``leap``), a hand folder or a path to a hand file → the hand file's path."""
    p = Path(name_or_path)
    if (p / HARDWARE_FILE).is_file():
        return p / HARDWARE_FILE
    if p.suffix in (".yaml", ".yml"):
        if not p.is_file():
            raise ConfigError(f"{p}: no such hand file", "check the path")
        return p
    candidate = hand_dir(name_or_path) / HARDWARE_FILE
    if not candidate.is_file():
        known = ", ".join(shipped_hand_configs())
        raise ConfigError(f"no hardware driver file for hand '{name_or_path}'",
                          f"use one of: {known}, 'sim' (simulated), or a path to a hand file")
    return candidate


def load_yaml_model(path: Path, model: type[M], doc_hint: str) -> M:
    """A YAML file (safe_load) validated as ``model``; one-line errors naming the file and field."""
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: malformed YAML: {' '.join(str(exc).split())}", "fix the YAML syntax") from None
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
        msg = f"unknown key '{loc}'" if err["type"] == "extra_forbidden" else err["msg"]
        raise ConfigError(f"{path}: field '{loc}': {msg}", f"see {doc_hint}") from None


def load_hand_config(name_or_path: str) -> HandConfig:
    return load_yaml_model(hand_config_path(name_or_path), HandConfig, "docs/deploy.md (hand files)")
