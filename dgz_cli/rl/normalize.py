"""Reward scaling by the running std of the discounted return (as SB3's VecNormalize does).

The paper's rewards summed with γ = 0.996 give returns in the hundreds; a critic that shares the
encoder then sees value losses in the thousands whose gradients swamp the policy's. Dividing each
reward by the running std of the discounted return keeps value targets O(1) without changing the
optimal policy. The statistics are saved in checkpoints.
"""

from __future__ import annotations

import numpy as np


class ReturnNormalizer:
    def __init__(self, num_envs: int, gamma: float, clip: float = 10.0, eps: float = 1e-8) -> None:
        self.gamma, self.clip, self.eps = gamma, clip, eps
        self.ret = np.zeros(num_envs)
        self.mean, self.var, self.count = 0.0, 1.0, 1e-4

    def _update(self, x: np.ndarray) -> None:
        b_mean, b_var, b_count = float(x.mean()), float(x.var()), x.size
        delta, total = b_mean - self.mean, self.count + b_count
        self.mean += delta * b_count / total
        m2 = self.var * self.count + b_var * b_count + delta ** 2 * self.count * b_count / total
        self.var, self.count = m2 / total, total

    def __call__(self, reward: np.ndarray, done: np.ndarray) -> np.ndarray:
        """(B,) rewards → scaled rewards; ``done`` (B,) ends the discounted sum of those envs."""
        self.ret = self.ret * self.gamma + reward
        self._update(self.ret)
        self.ret[done] = 0.0
        return np.clip(reward / np.sqrt(self.var + self.eps), -self.clip, self.clip)

    def state(self) -> dict:
        return dict(mean=self.mean, var=self.var, count=self.count)

    def load(self, state: dict) -> None:
        self.mean, self.var, self.count = float(state["mean"]), float(state["var"]), float(state["count"])
