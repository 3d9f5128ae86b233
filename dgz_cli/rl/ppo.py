"""PPO (clipped surrogate, clipped value loss, adaptive-KL learning rate) for graph actor-critics.

Defaults follow the paper's Table S1 (γ 0.996, λ 0.95, ε 0.2, Adam 5e-4 with adaptive KL, grad-norm 0.5,
4 epochs × 4 mini-batches); the value-loss coefficient (1.0), entropy coefficient (0.0), desired KL (0.01)
and advantage normalization are not given by the paper and follow rsl_rl.

The policy is an ``nn.Module`` with ``forward(obs) -> (mean (B, A), log_std (B, A), value (B,))``,
``sample(obs)`` (a rollout action and its statistics) and ``action_valid(obs)`` (B, A) over the control
contract's action layout, e.g. :class:`dgz_cli.policy.MAGCN`. Log-probs, entropies and KLs are summed over
valid action dims only.

Typical loop::

    ppo = PPO(policy, learning_rate=5e-4)   # or PPO(policy, PPOConfig(...))
    storage = RolloutStorage(T, B)        # buffers are allocated on the first add
    for t in range(T):
        out = ppo.act(to_tensors(obs))
        obs_next, r, term, trunc, info = env.step(out["action"].numpy())
        storage.add(obs, reward=r, terminated=term, truncated=trunc, **out)
        obs = obs_next
    stats = ppo.update(storage, ppo.value(to_tensors(obs)))   # GAE from V(s_T), then clears the storage
"""

from __future__ import annotations

import math
from typing import Literal

import torch
from torch import nn

from dgz_cli.policy.magcn import gaussian_entropy, gaussian_kl, gaussian_log_prob
from dgz_cli.rl.config import PPOConfig
from dgz_cli.rl.schedule import AdaptiveKLSchedule
from dgz_cli.rl.storage import RolloutStorage


class PPO:
    def __init__(self, policy: nn.Module, config: PPOConfig | None = None, *, gamma: float = 0.996, lam: float = 0.95, clip_param: float = 0.2,
                 learning_rate: float = 5e-4, schedule: Literal["adaptive", "fixed"] = "adaptive",
                 desired_kl: float = 0.01, min_lr: float = 1e-5, max_lr: float = 1e-2, max_grad_norm: float = 0.5,
                 num_epochs: int = 4, num_mini_batches: int = 4, value_loss_coef: float = 1.0,
                 entropy_coef: float = 0.0, use_clipped_value_loss: bool = True,
                 normalize_advantages: bool = True) -> None:
        """Hyper-parameters come either from ``config`` or from the keywords (validated via :class:`PPOConfig`)."""
        kw = dict(gamma=gamma, lam=lam, clip_param=clip_param, learning_rate=learning_rate, schedule=schedule,
                  desired_kl=desired_kl, min_lr=min_lr, max_lr=max_lr, max_grad_norm=max_grad_norm,
                  num_epochs=num_epochs, num_mini_batches=num_mini_batches, value_loss_coef=value_loss_coef,
                  entropy_coef=entropy_coef, use_clipped_value_loss=use_clipped_value_loss,
                  normalize_advantages=normalize_advantages)
        if config is None:
            config = PPOConfig(**kw)
        elif PPOConfig(**kw) != PPOConfig():
            raise ValueError("pass hyper-parameters either as a PPOConfig or as keywords, not both")
        self.cfg = c = config
        self.policy = policy
        self.optimizer = torch.optim.Adam(policy.parameters(), lr=c.learning_rate)
        self.schedule = (AdaptiveKLSchedule(c.learning_rate, c.desired_kl, c.min_lr, c.max_lr)
                         if c.schedule == "adaptive" else None)

    def enforce_std_bounds(self) -> None:
        """Keep the policy's exploration std within ``[min_std, max_std]`` (a bound of 0 is off)."""
        c = self.cfg
        if c.min_std > 0 or c.max_std > 0:
            self.policy.clamp_log_std(math.log(c.min_std) if c.min_std > 0 else None,
                                      math.log(c.max_std) if c.max_std > 0 else None)

    @property
    def learning_rate(self) -> float:
        return self.optimizer.param_groups[0]["lr"]

    def set_learning_rate(self, lr: float) -> None:
        for g in self.optimizer.param_groups:
            g["lr"] = lr
        if self.schedule is not None:
            self.schedule.lr = lr

    def optimizer_tensors(self) -> dict[str, torch.Tensor]:
        """Adam state as flat ``{"<param index>.<name>": tensor}`` (safetensors-friendly, no pickle)."""
        st = self.optimizer.state_dict()["state"]
        return {f"{i}.{k}": torch.as_tensor(v) for i, s in st.items() for k, v in s.items()}

    def load_optimizer_tensors(self, tensors: dict[str, torch.Tensor], learning_rate: float | None = None) -> None:
        """Inverse of :meth:`optimizer_tensors`; also restores the (adapted) learning rate if given."""
        sd = self.optimizer.state_dict()
        state: dict[int, dict[str, torch.Tensor]] = {}
        for key, v in tensors.items():
            i, name = key.split(".", 1)
            state.setdefault(int(i), {})[name] = v
        self.optimizer.load_state_dict({"state": state, "param_groups": sd["param_groups"]})
        if learning_rate is not None:
            self.set_learning_rate(float(learning_rate))

    def act(self, obs: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """Sample actions for a rollout (the policy's ``sample``): action, log_prob, value, mean, log_std
        (keys match ``storage.add``)."""
        return self.policy.sample(obs)

    @torch.no_grad()
    def value(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        """V(obs) (B,)."""
        return self.policy(obs)[2]

    def compute_returns(self, storage: RolloutStorage, last_obs: dict[str, torch.Tensor]) -> None:
        """Bootstrap from V(last_obs) and fill ``storage.advantages`` / ``storage.returns``."""
        storage.compute_returns(self.value(last_obs), self.cfg.gamma, self.cfg.lam)

    def update(self, storage: RolloutStorage, last_value: torch.Tensor | None = None,
               critic_only: bool = False) -> dict[str, float]:
        """``num_epochs`` × ``num_mini_batches`` gradient steps; returns mean losses, KL, clip fraction, final lr.

        ``last_value`` (B,) = V(s_T) computes the returns here; without it :meth:`compute_returns` must have
        been called. The storage is cleared afterwards. ``critic_only``: the steps fit the value alone (only
        :meth:`MAGCN.critic_parameters` move, the learning-rate schedule is not stepped), so the actor's
        behaviour is unchanged.
        """
        c = self.cfg
        if last_value is not None:
            storage.compute_returns(last_value, c.gamma, c.lam)
        keys = ("loss", "surrogate_loss", "value_loss", "entropy", "kl", "clip_fraction", "grad_norm")
        acc = {k: 0.0 for k in keys}
        n = 0
        critic = {id(p) for p in self.policy.critic_parameters()} if critic_only else set()
        self.policy.train()
        for _ in range(c.num_epochs):
            for mb in storage.mini_batches(c.num_mini_batches, c.normalize_advantages):
                mean, log_std, value = self.policy(mb.obs)
                av = self.policy.action_valid(mb.obs)
                log_prob = gaussian_log_prob(mean, log_std, mb.actions, av)
                entropy = gaussian_entropy(log_std, av).mean()
                log_ratio = log_prob - mb.old_log_prob
                ratio = torch.exp(log_ratio)
                with torch.no_grad():
                    if storage.has_dist:
                        kl = gaussian_kl(mb.old_mean, mb.old_log_std, mean, log_std, av).mean()
                    else:  # k3 estimator of KL(old ‖ new)
                        kl = ((ratio - 1.0) - log_ratio).mean()
                if self.schedule is not None and not critic_only:
                    self.set_learning_rate(self.schedule.step(kl.item()))
                adv = mb.advantages
                surrogate = -torch.min(ratio * adv, ratio.clamp(1.0 - c.clip_param, 1.0 + c.clip_param) * adv).mean()
                if c.use_clipped_value_loss:
                    v_clip = mb.old_values + (value - mb.old_values).clamp(-c.clip_param, c.clip_param)
                    value_loss = torch.max((value - mb.returns) ** 2, (v_clip - mb.returns) ** 2).mean()
                else:
                    value_loss = ((value - mb.returns) ** 2).mean()
                loss = surrogate + c.value_loss_coef * value_loss - c.entropy_coef * entropy
                self.optimizer.zero_grad(set_to_none=True)
                if critic_only:
                    (c.value_loss_coef * value_loss).backward()
                    for p in self.policy.parameters():
                        if id(p) not in critic:
                            p.grad = None
                else:
                    loss.backward()
                grad_norm = nn.utils.clip_grad_norm_(self.policy.parameters(), c.max_grad_norm)
                self.optimizer.step()
                self.enforce_std_bounds()
                clip_frac = ((ratio - 1.0).abs() > c.clip_param).float().mean()
                for k, v in zip(keys, (loss, surrogate, value_loss, entropy, kl, clip_frac, grad_norm)):
                    acc[k] += float(v.detach())
                n += 1
        storage.clear()
        out = {k: v / max(1, n) for k, v in acc.items()}
        out.update(learning_rate=self.learning_rate, num_updates=float(n))
        return out
