"""The safety filter between a policy and a hand.

Per control step: reject a non-finite or wrongly shaped action; clip α to ±finger_clip (0.015 rad) and the
wrist command to ±wrist_clip (0.01); map through M_h; cap every joint's change to
min(max_joint_step, velocity_limit·dt); integrate on the previous *target* (never the measured position);
clip to the narrower of the spec's and the device's limits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgz_cli.runtime.mapping import MhMap
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec


class UnsafeAction(DgzError):
    """The policy produced something the filter refuses to pass on (NaN, wrong size)."""


@dataclass(frozen=True)
class SafetyConfig:
    finger_clip: float = 0.015     # |α| per step, rad (paper: 0.015)
    wrist_clip: float = 0.01       # |wrist command| per step (paper: 0.01)
    max_joint_step: float = 0.02   # rad per step, whatever the velocity limit says


@dataclass
class SafeCommand:
    target: np.ndarray       # joint targets, rad, spec order
    wrist: np.ndarray        # clipped wrist command (6)
    alpha: np.ndarray        # clipped α (N_nodes, 3)
    dq: np.ndarray           # applied joint change
    limited: bool            # True if any clip, cap or limit changed the request


class SafetyFilter:
    def __init__(self, spec: HandSpec, device_limits: tuple[np.ndarray, np.ndarray] | None, dt: float,
                 cfg: SafetyConfig = SafetyConfig()) -> None:
        self.cfg = cfg
        self.mh = MhMap(spec)
        self.names = [j.joint for j in spec.joints]
        lo = np.array([j.lower for j in spec.joints], dtype=float)
        hi = np.array([j.upper for j in spec.joints], dtype=float)
        if device_limits is not None:
            lo = np.maximum(lo, np.asarray(device_limits[0], dtype=float))
            hi = np.minimum(hi, np.asarray(device_limits[1], dtype=float))
        bad = [n for n, a, b in zip(self.names, lo, hi) if a > b]
        if bad:
            raise DgzError(f"joint(s) {bad}: the spec's and the device's limits do not overlap",
                           "check the channel offsets/signs in the hand file against the spec")
        self.lo, self.hi = lo, hi
        vel = np.array([j.velocity for j in spec.joints], dtype=float)
        self.cap = np.where(vel > 0, np.minimum(cfg.max_joint_step, vel * dt), cfg.max_joint_step)
        self.target: np.ndarray | None = None

    def reset(self, q0) -> np.ndarray:
        """Start integrating from ``q0`` (clipped into the limits)."""
        self.target = np.clip(np.asarray(q0, dtype=float), self.lo, self.hi)
        return self.target.copy()

    def check(self, action) -> np.ndarray:
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (self.mh.action_dim,):
            raise UnsafeAction(f"policy returned {a.size} numbers, expected {self.mh.action_dim} "
                               f"(6 wrist + 3 × {self.mh.n_nodes} nodes)",
                               "the policy was built for another hand: load the one for this spec")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise UnsafeAction(f"policy returned a non-finite action (index {int(bad[0])} = {a[bad[0]]})",
                               "the policy diverged: check its inputs (observation scaling) and checkpoint")
        return a

    def step(self, action) -> SafeCommand:
        if self.target is None:
            raise RuntimeError("SafetyFilter.reset() must be called first")
        a = self.check(action)
        wrist, alpha = self.mh.split(a)
        wrist_c = np.clip(wrist, -self.cfg.wrist_clip, self.cfg.wrist_clip)
        alpha_c = np.clip(alpha, -self.cfg.finger_clip, self.cfg.finger_clip)
        dq_req = self.mh.delta_q(alpha_c)
        dq = np.clip(dq_req, -self.cap, self.cap)
        target = np.clip(self.target + dq, self.lo, self.hi)
        limited = bool(np.any(wrist_c != wrist) or np.any(alpha_c != alpha) or np.any(dq != dq_req)
                       or np.any(target != self.target + dq))
        dq_applied = target - self.target
        self.target = target
        return SafeCommand(target.copy(), wrist_c, alpha_c, dq_applied, limited)

    def approach(self, goal, max_step: float) -> np.ndarray:
        """One ramp step of the target toward ``goal`` (each joint by at most ``max_step``)."""
        goal = np.clip(np.asarray(goal, dtype=float), self.lo, self.hi)
        self.target = self.target + np.clip(goal - self.target, -max_step, max_step)
        return self.target.copy()
