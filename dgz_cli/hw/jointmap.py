"""Channel (device order, native units) ↔ HandSpec joint (spec ``joints`` order, radians).

See :mod:`dgz_cli.hw.config` for the three conversions. Commands are clipped to each channel's native
range before rounding, so a target outside the device's range can never reach the wire.
"""

from __future__ import annotations

import math

import numpy as np

from dgz_cli.hw.config import HandConfig
from dgz_cli.hw.errors import ConfigError
from dgz_cli.spec.models import HandSpec


class JointMapper:
    def __init__(self, cfg: HandConfig, spec: HandSpec, device_limits_deg: list[tuple[float, float]] | None = None,
                 where: str = "") -> None:
        where = where or f"hand file '{cfg.name}'"
        spec_joints = [j.joint for j in spec.joints]
        by_joint = {c.joint: i for i, c in enumerate(cfg.channels)}
        unknown = [c.joint for c in cfg.channels if c.joint not in spec_joints]
        if unknown:
            raise ConfigError(f"{where}: channels drive joints not in spec '{spec.name}': {unknown}",
                              f"use joint names from hand_specs/{spec.name}.yaml (joints[].joint)")
        missing = [j for j in spec_joints if j not in by_joint]
        if missing:
            raise ConfigError(f"{where}: spec '{spec.name}' joints have no channel: {missing}",
                              "add a channel for every actuated joint of the spec")
        self.cfg = cfg
        self.joint_names = spec_joints
        self.n = len(spec_joints)
        # perm[k] = channel index that drives spec joint k
        self.perm = np.array([by_joint[j] for j in spec_joints], dtype=int)
        chans = cfg.channels
        self.sign = np.array([chans[i].sign for i in self.perm], dtype=float)
        self.offset = np.array([chans[i].offset for i in self.perm], dtype=float)
        self.nlo = np.array([chans[i].native[0] for i in self.perm], dtype=float)
        self.nhi = np.array([chans[i].native[1] for i in self.perm], dtype=float)
        if cfg.conversion == "spec_limits":
            self.lower = np.array([j.lower for j in spec.joints])
            self.upper = np.array([j.upper for j in spec.joints])
        elif cfg.conversion == "device_limits":
            if device_limits_deg is None or len(device_limits_deg) != len(chans):
                raise ConfigError(f"{where}: conversion 'device_limits' needs the limits read from the device",
                                  "connect first (the driver reads them at connect)")
            lim = np.radians(np.array(device_limits_deg, dtype=float))[self.perm]
            if np.any(lim[:, 1] <= lim[:, 0]):
                raise ConfigError(f"{where}: the device reports empty position limits {device_limits_deg} (deg)",
                                  "check the firmware's unit mode and calibration (vendor tool)")
            self.lower, self.upper = lim[:, 0], lim[:, 1]
        else:
            self.lower = self.upper = None

    # native (channel order) → rad (spec order)
    def to_rad(self, native) -> np.ndarray:
        n = np.asarray(native, dtype=float)[self.perm]
        if self.cfg.conversion == "linear":
            return self.sign * n * self.cfg.rad_per_unit + self.offset
        u = (n - self.nlo) / (self.nhi - self.nlo)
        f = np.where(self.sign > 0, u, 1.0 - u)
        return self.lower + f * (self.upper - self.lower) + self.offset

    # rad (spec order) → native ints (channel order), clipped to the native range
    def to_native(self, q) -> list[int]:
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n,) or not np.all(np.isfinite(q)):
            raise ValueError(f"expected {self.n} finite joint values, got {q!r}")
        if self.cfg.conversion == "linear":
            n = (q - self.offset) / (self.sign * self.cfg.rad_per_unit)
        else:
            f = (q - self.offset - self.lower) / (self.upper - self.lower)
            u = np.where(self.sign > 0, f, 1.0 - f)
            n = self.nlo + u * (self.nhi - self.nlo)
        n = np.clip(np.rint(n), self.nlo, self.nhi)
        out = [0] * self.n
        for k, ch in enumerate(self.perm):
            out[ch] = int(n[k])
        return out

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """The device's reachable range in rad (spec order), from the native range."""
        a = self.to_rad_spec_order(self.nlo)
        b = self.to_rad_spec_order(self.nhi)
        return np.minimum(a, b), np.maximum(a, b)

    def to_rad_spec_order(self, n_spec: np.ndarray) -> np.ndarray:
        native = np.zeros(self.n)
        native[self.perm] = n_spec
        return self.to_rad(native)

    def reorder(self, values_by_channel) -> np.ndarray:
        """Per-channel values (current, force) → spec joint order."""
        return np.asarray(values_by_channel, dtype=float)[self.perm]


TICKS_PER_REV = 4096
RAD_PER_TICK = 2 * math.pi / TICKS_PER_REV
