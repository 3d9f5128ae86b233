"""Rollout storage for T steps × B envs of dict observations, GAE(λ), and shuffled mini-batches.

Tensors live on CPU (or ``device``). Keys in ``static_keys`` (per-slot constants such as the adjacency and
physical features, ~70 % of an observation) are stored once per env instead of once per step; ``add``
checks that they did not change.

Episode ends (Gymnasium semantics): ``terminated`` → no bootstrap; ``truncated`` (the time limit or an
instability, and not terminated) → bootstrap with ``final_value`` (B,), the value of the episode's last
observation (``GraspEnv`` returns it in ``info["final_obs"]``, since it resets a finished slot in place), or
with the value of the step's own observation when the caller has none (the rsl_rl approximation).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator, Mapping

import numpy as np
import torch

STATIC_KEYS = ("adjacency", "physical", "mask", "node_valid")


def _t(x, device, dtype=None) -> torch.Tensor:
    t = x if isinstance(x, torch.Tensor) else torch.as_tensor(np.asarray(x))
    return t.to(device=device, dtype=dtype or (torch.bool if t.dtype in (torch.bool,) else torch.float32))


@dataclass
class MiniBatch:
    obs: dict[str, torch.Tensor]
    actions: torch.Tensor        # (M, A)
    old_log_prob: torch.Tensor   # (M,)
    old_values: torch.Tensor     # (M,)
    advantages: torch.Tensor     # (M,)
    returns: torch.Tensor        # (M,)
    old_mean: torch.Tensor       # (M, A)
    old_log_std: torch.Tensor    # (M, A)


class RolloutStorage:
    def __init__(self, num_steps: int, num_envs: int, obs_example: Mapping | None = None, action_dim: int | None = None,
                 device: str | torch.device = "cpu", static_keys: tuple[str, ...] = STATIC_KEYS, seed: int = 0) -> None:
        """Buffers are allocated from ``obs_example`` / ``action_dim`` or, if omitted, on the first :meth:`add`."""
        self.T, self.B, self.device = num_steps, num_envs, torch.device(device)
        self._static_request, self.obs = tuple(static_keys), {}
        self.A: int | None = None
        self.env_priority: torch.Tensor | None = None  # (B,) sampling weights of the envs' transitions; None = uniform
        self.clear()
        self.generator = torch.Generator().manual_seed(seed)
        if obs_example is not None and action_dim is not None:
            self._allocate(obs_example, action_dim)

    def _allocate(self, obs_example: Mapping, action_dim: int) -> None:
        T, B, dev = self.T, self.B, self.device
        self.A = action_dim
        self.static_keys = tuple(k for k in self._static_request if k in obs_example)
        for k, v in obs_example.items():
            v = _t(v, dev)
            if v.shape[0] != B:
                raise ValueError(f"obs[{k!r}] has batch {v.shape[0]}, expected {B}")
            lead = () if k in self.static_keys else (T,)
            self.obs[k] = torch.zeros(lead + tuple(v.shape), dtype=v.dtype, device=dev)
        z = lambda *s, dt=torch.float32: torch.zeros(*s, dtype=dt, device=dev)  # noqa: E731
        self.actions, self.mean, self.log_std = z(T, B, action_dim), z(T, B, action_dim), z(T, B, action_dim)
        self.log_prob, self.values, self.rewards = z(T, B), z(T, B), z(T, B)
        self.bootstrap = z(T, B)  # value used after a truncation (0 elsewhere)
        self.terminated, self.truncated = z(T, B, dt=torch.bool), z(T, B, dt=torch.bool)
        self.advantages, self.returns = z(T, B), z(T, B)

    def clear(self) -> None:
        self.step, self.has_returns, self.has_dist = 0, False, True

    @property
    def full(self) -> bool:
        return self.step == self.T

    def add(self, obs: Mapping, action, log_prob, value, reward, terminated, truncated, mean=None, log_std=None,
            final_value=None) -> None:
        """Store the transition (obs_t, a_t, ...) → (r_t, terminated_t, truncated_t); arrays are (B, ...)."""
        if self.step >= self.T:
            raise RuntimeError("rollout storage is full; call clear() after the update")
        if self.A is None:
            self._allocate(obs, int(np.shape(action)[-1]))
        t, dev = self.step, self.device
        for k, buf in self.obs.items():
            v = _t(obs[k], dev, buf.dtype)
            if k in self.static_keys:
                if t == 0:
                    buf.copy_(v)
                elif not torch.equal(buf, v):
                    raise ValueError(f"static observation {k!r} changed during the rollout")
            else:
                buf[t].copy_(v)
        self.actions[t] = _t(action, dev)
        self.log_prob[t], self.values[t], self.rewards[t] = _t(log_prob, dev), _t(value, dev), _t(reward, dev)
        if mean is None or log_std is None:
            self.has_dist = False  # PPO then estimates the KL from log-prob ratios
        else:
            self.mean[t], self.log_std[t] = _t(mean, dev), _t(log_std, dev)
        term, trunc = _t(terminated, dev, torch.bool), _t(truncated, dev, torch.bool)
        self.terminated[t], self.truncated[t] = term, trunc
        boot = self.values[t] if final_value is None else _t(final_value, dev)
        self.bootstrap[t] = torch.where(trunc & ~term, boot, torch.zeros_like(boot))
        self.step += 1

    @torch.no_grad()
    def compute_returns(self, last_value, gamma: float, lam: float) -> None:
        """GAE(λ): next value is V(s_{t+1}) if the episode continues, the bootstrap value after a truncation,
        0 after a termination; the GAE trace is cut at every episode end. ``last_value`` (B,) is V(s_T)."""
        if not self.full:
            raise RuntimeError(f"compute_returns on a partial rollout ({self.step}/{self.T} steps)")
        next_v, gae = _t(last_value, self.device), torch.zeros(self.B, device=self.device)
        for t in reversed(range(self.T)):
            ended = self.terminated[t] | self.truncated[t]
            nv = torch.where(ended, self.bootstrap[t], next_v)
            delta = self.rewards[t] + gamma * nv - self.values[t]
            gae = delta + gamma * lam * (~ended).float() * gae
            self.advantages[t] = gae
            next_v = self.values[t]
        self.returns = self.advantages + self.values
        self.has_returns = True

    def set_env_priority(self, priority) -> None:
        """(B,) non-negative weights: mini-batches then draw transitions with replacement, env b's with probability
        ∝ priority[b] (prioritised sampling of failing pairs); None restores the uniform shuffled pass."""
        if priority is None:
            self.env_priority = None
            return
        w = _t(priority, self.device, torch.float64)
        if w.shape != (self.B,) or not torch.isfinite(w).all() or (w < 0).any() or w.sum() <= 0:
            raise ValueError(f"env priorities must be {self.B} finite non-negative weights, not all zero")
        self.env_priority = w

    def mini_batches(self, num_mini_batches: int, normalize_advantages: bool = True) -> Iterator[MiniBatch]:
        """One shuffled pass over the T·B transitions in ``num_mini_batches`` batches (seeded generator); with
        env priorities, T·B draws with replacement, weighted by the env's priority."""
        if not self.has_returns:
            raise RuntimeError("call compute_returns() before sampling mini-batches")
        n = self.T * self.B
        size = n // num_mini_batches
        if size == 0:
            raise ValueError(f"{num_mini_batches} mini-batches for only {n} transitions")
        adv = self.advantages.flatten()
        if normalize_advantages:
            adv = (adv - adv.mean()) / (adv.std() + 1e-8)
        if self.env_priority is None:
            perm = torch.randperm(n, generator=self.generator).to(self.device)
        else:  # flat index t·B + b carries env b's weight
            perm = torch.multinomial(self.env_priority.repeat(self.T), n, replacement=True, generator=self.generator)
        flat = lambda x: x.reshape(n, *x.shape[2:])  # noqa: E731
        for i in range(num_mini_batches):
            idx = perm[i * size:(i + 1) * size]
            env = idx % self.B  # flat index = t·B + b
            obs = {k: (buf[env] if k in self.static_keys else flat(buf)[idx]) for k, buf in self.obs.items()}
            yield MiniBatch(obs, flat(self.actions)[idx], flat(self.log_prob)[idx], flat(self.values)[idx], adv[idx],
                            flat(self.returns)[idx], flat(self.mean)[idx], flat(self.log_std)[idx])
