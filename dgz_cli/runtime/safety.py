"""The safety filter between a policy and a hand.

Per control step: reject a non-finite or wrongly shaped action; clip it to [-1, 1] and scale it by the
control contract (the same clip and scales as the simulator); map the finger part through M_h with the
contract's :func:`~dgz_cli.spec.contract.finger_targets`, capping every joint's change to
min(max_joint_step, velocity_limit·dt); integrate on the previous *target* (never the measured position);
clip to the narrower of the spec's and the device's limits. At the contract's scales the cap does not bind
on the shipped hands (finger_scale 0.015 rad ≤ every cap), so the targets equal the simulator's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgz_cli.runtime.mapping import MhMap
from dgz_cli.spec.contract import ControlContract, finger_targets
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec


class UnsafeAction(DgzError):
    """The policy produced something the filter refuses to pass on (NaN, wrong size)."""


@dataclass(frozen=True)
class SafetyConfig:
    max_joint_step: float = 0.02   # rad per step, whatever the velocity limit says


@dataclass
class SafeCommand:
    target: np.ndarray       # joint targets, rad, spec order
    wrist: np.ndarray        # wrist command (6), m and rad, palm frame
    action: np.ndarray       # the normalized action after the [-1, 1] clip (action_dim,)
    dq: np.ndarray           # applied joint change
    limited: bool            # True if any clip, cap or limit changed the request


class SafetyFilter:
    def __init__(self, spec: HandSpec, device_limits: tuple[np.ndarray, np.ndarray] | None, contract: ControlContract,
                 cfg: SafetyConfig = SafetyConfig()) -> None:
        self.cfg, self.contract = cfg, contract
        self.mh = MhMap(spec)
        self.names = [j.joint for j in spec.joints]
        lo = np.array([j.lower for j in spec.joints], dtype=float)
        hi = np.array([j.upper for j in spec.joints], dtype=float)
        if device_limits is not None:
            lo = np.maximum(lo, np.asarray(device_limits[0], dtype=float))
            hi = np.minimum(hi, np.asarray(device_limits[1], dtype=float))
        bad = [n for n, a, b in zip(self.names, lo, hi) if not a <= b]
        if bad:
            raise DgzError(f"joint(s) {bad}: the spec's and the device's limits do not overlap",
                           "check the channel offsets/signs in the hand file against the spec")
        self.lo, self.hi = lo, hi
        dt = 1.0 / contract.episode.control_hz
        vel = np.array([j.velocity for j in spec.joints], dtype=float)
        self.cap = np.where(vel > 0, np.minimum(cfg.max_joint_step, vel * dt), cfg.max_joint_step)
        self.action_dim = contract.action.dim(self.mh.n_nodes)
        self.target: np.ndarray | None = None

    def reset(self, q0) -> np.ndarray:
        """Start integrating from ``q0`` (clipped into the limits)."""
        self.target = np.clip(np.asarray(q0, dtype=float), self.lo, self.hi)
        return self.target.copy()

    def check(self, action) -> np.ndarray:
        a = np.asarray(action, dtype=float).reshape(-1)
        if a.shape != (self.action_dim,):
            raise UnsafeAction(f"policy returned {a.size} numbers, expected {self.action_dim} "
                               f"({self.contract.action.wrist_dim} wrist + {self.contract.action.n_prim} × "
                               f"{self.mh.n_nodes} nodes)",
                               "the policy was built for another hand: load the one for this spec")
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise UnsafeAction(f"policy returned a non-finite action (index {int(bad[0])} = {a[bad[0]]})",
                               "the policy diverged: check its inputs (observation scaling) and checkpoint")
        return a

    def step(self, action, q: np.ndarray | None = None) -> SafeCommand:
        """One normalized action (action_dim,) → the joint targets and the wrist command to send; ``q`` (L,)
        the measured joints, for the contract's finger lead cap."""
        if self.target is None:
            raise RuntimeError("SafetyFilter.reset() must be called first")
        a = self.check(action)
        act = self.contract.action
        clipped = np.clip(a, -1.0, 1.0)
        alpha = clipped[act.wrist_dim:].reshape(1, self.mh.n_nodes, act.n_prim)
        row = lambda v: np.asarray(v)[None]  # noqa: E731 — one hand = a batch of one
        target = finger_targets(row(self.target), alpha, row(self.mh.node), row(self.mh.prim), row(self.mh.sign),
                                row(self.mh.slot), row(self.lo), row(self.hi), act, step_cap=row(self.cap),
                                q=None if q is None else row(np.asarray(q, dtype=float)))[0]
        free = finger_targets(row(self.target), alpha, row(self.mh.node), row(self.mh.prim), row(self.mh.sign),
                              row(self.mh.slot), row(np.full_like(self.lo, -np.inf)), row(np.full_like(self.hi, np.inf)),
                              act, q=None if q is None else row(np.asarray(q, dtype=float)))[0]
        limited = bool(np.any(clipped != a) or np.any(target != free))
        dq = target - self.target
        self.target = target
        return SafeCommand(target.copy(), clipped[:act.wrist_dim] * act.wrist_scale, clipped, dq, limited)

    def approach(self, goal, max_step: float) -> np.ndarray:
        """One ramp step of the target toward ``goal`` (each joint by at most ``max_step``)."""
        goal = np.clip(np.asarray(goal, dtype=float), self.lo, self.hi)
        self.target = self.target + np.clip(goal - self.target, -max_step, max_step)
        return self.target.copy()
