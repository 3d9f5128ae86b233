"""Behaviour-cloning warm start from the spec-only scripted grasp (before PPO).

PPO from a random MAGCN on this CPU budget learns to reach and touch objects but not to close and
hold them (policies/dgz-cpu-first: success 0.00 after 105 iterations). The scripted controller of
:mod:`dgz_cli.sim.scripted` uses nothing but the HandSpec, so cloning it keeps the method
hand-agnostic: the actor's mean is regressed onto the scripted actions and the critic onto the
discounted (reward-scaled) returns of the same rollouts, then PPO improves on it with the paper's
reward. This is a deviation from the paper (which trains from scratch); it is recorded in the
checkpoint's config (``bc_episodes`` > 0).

Data are collected in whole episodes: every slot starts an episode at ``env.reset`` and episodes
have a fixed length, so Monte-Carlo returns need no bootstrap.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from dgz_cli.policy.graph import to_tensors
from dgz_cli.rl.normalize import ReturnNormalizer
from dgz_cli.rl.storage import STATIC_KEYS


@dataclass
class Demonstrations:
    """T steps × B slots. ``steps[k]`` holds the per-step observation keys, ``static`` the per-slot ones."""

    static: dict[str, torch.Tensor]     # adjacency (B,N,N), physical (B,N,27), mask (B,N,3), node_valid (B,N)
    nodes: torch.Tensor                 # (T, B, N, node_dim)
    global_: torch.Tensor               # (T, B, global_dim)
    actions: torch.Tensor               # (T, B, A) scripted actions in [-1, 1]
    returns: torch.Tensor               # (T, B) discounted returns of the scaled rewards
    success_rate: float                 # of the episodes collected (by whoever acted)
    episodes: int

    @staticmethod
    def concat(parts: list["Demonstrations"]) -> "Demonstrations":
        """Aggregate collections from the same env along time (DAgger's growing dataset)."""
        return Demonstrations(static=parts[0].static, nodes=torch.cat([p.nodes for p in parts]),
                              global_=torch.cat([p.global_ for p in parts]),
                              actions=torch.cat([p.actions for p in parts]),
                              returns=torch.cat([p.returns for p in parts]),
                              success_rate=parts[-1].success_rate, episodes=sum(p.episodes for p in parts))

    def obs(self, t: torch.Tensor, b: torch.Tensor) -> dict[str, torch.Tensor]:
        """Observation batch of the (t, b) index pairs (M,) each."""
        out = {k: v[b] for k, v in self.static.items()}
        out["nodes"], out["global"] = self.nodes[t, b], self.global_[t, b]
        return out


def collect(env, teacher, episodes: int, normalizer: ReturnNormalizer, gamma: float, seed: int,
            student: nn.Module | None = None, check_stop: Callable[[], None] = lambda: None) -> Demonstrations:
    """Roll ``episodes`` whole episodes in every slot of ``env`` (a ``GraspEnv``), labelled with the actions
    of ``teacher`` (``act(obs)`` / ``reset(mask)``, e.g. the scripted grasp of :mod:`dgz_cli.sim.scripted`).

    Without ``student`` the scripted grasp acts (plain behaviour cloning); with it the student's mean
    action is executed while the teacher still labels every visited state (DAgger: the clone then learns
    what to do in the states its own mistakes lead to). ``normalizer`` is updated with the rewards (so
    PPO starts from the same scale) and scales them. ``check_stop`` is called before every step (it raises
    to stop, :class:`dgz_cli.rl.stop.StopRequest`).
    """
    obs = env.reset(seed)
    teacher.reset(None)
    first = to_tensors(obs)
    static = {k: first[k].clone() for k in STATIC_KEYS}
    nodes, glob, actions, rewards, dones = [], [], [], [], []
    successes: list[bool] = []
    steps = episodes * env.cfg.contract.episode.episode_steps
    for _ in range(steps):
        check_stop()
        a = teacher.act(obs)  # the teacher follows the visited states, whoever acts
        executed = a
        if student is not None:
            executed = student.act(to_tensors(obs)).numpy()
        nodes.append(torch.as_tensor(obs["nodes"], dtype=torch.float32).clone())
        glob.append(torch.as_tensor(obs["global"], dtype=torch.float32).clone())
        actions.append(torch.as_tensor(a, dtype=torch.float32))
        obs, reward, terminated, truncated, info = env.step(executed)
        done = terminated | truncated
        rewards.append(normalizer(reward.astype(np.float64), done))
        dones.append(done)
        successes += [e["success"] for e in info["episode"].values()]
        if done.any():
            teacher.reset(done)
    returns = discounted_returns(np.stack(rewards), np.stack(dones), gamma)
    return Demonstrations(static=static, nodes=torch.stack(nodes), global_=torch.stack(glob),
                          actions=torch.stack(actions), returns=torch.as_tensor(returns, dtype=torch.float32),
                          success_rate=float(np.mean(successes)) if successes else 0.0, episodes=len(successes))


def discounted_returns(rewards: np.ndarray, dones: np.ndarray, gamma: float) -> np.ndarray:
    """G_t = r_t + γ·G_{t+1}·(1 − done_t) over (T, B) arrays, zero after the last step."""
    ret = np.zeros(rewards.shape[1])
    out = np.zeros(rewards.shape)
    for t in range(rewards.shape[0] - 1, -1, -1):
        ret = rewards[t] + gamma * ret * ~dones[t]
        out[t] = ret
    return out


def pretrain(model: nn.Module, demos: Demonstrations, *, epochs: int = 10, mini_batch: int = 1024,
             learning_rate: float = 5e-4, value_coef: float = 1.0, max_grad_norm: float = 0.5,
             log_std: float | None = None, seed: int = 0,
             check_stop: Callable[[], None] = lambda: None) -> dict[str, float]:
    """Regress the actor's mean onto the demonstrated actions (MSE over valid action dims) and the
    critic onto their returns; then set the exploration log-std to ``log_std`` if given. ``check_stop`` is
    called before every mini-batch.
    Returns the final epoch's mean action and value losses."""
    T, B = demos.actions.shape[:2]
    opt = torch.optim.Adam(model.parameters(), lr=learning_rate)
    gen = torch.Generator().manual_seed(seed)
    model.train()
    stats = {}
    for _ in range(epochs):
        perm = torch.randperm(T * B, generator=gen)
        sums, n = np.zeros(2), 0
        for k in range(0, T * B, mini_batch):
            check_stop()
            idx = perm[k:k + mini_batch]
            t, b = idx // B, idx % B
            obs = demos.obs(t, b)
            mean, _, value = model(obs)
            av = model.action_valid(obs).float()
            action_loss = (((mean - demos.actions[t, b]) ** 2) * av).sum() / av.sum()
            value_loss = ((value - demos.returns[t, b]) ** 2).mean()
            loss = action_loss + value_coef * value_loss
            opt.zero_grad(set_to_none=True)
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), max_grad_norm)
            opt.step()
            sums += [action_loss.item(), value_loss.item()]
            n += 1
        stats = dict(bc_action_loss=float(sums[0] / n), bc_value_loss=float(sums[1] / n))
    if log_std is not None:
        with torch.no_grad():
            model.log_std_wrist.fill_(log_std)
            model.log_std_prim.fill_(log_std)
    model.eval()
    return stats
