"""Evaluation protocol: every (hand, object) pair × trials episodes, success per episode.

Slots are filled with (hand, object) pairs; each slot runs ``trials`` consecutive episodes with
its own seeded randomization (hand pose, object orientation). Returns per-episode records.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import ObjectModel
from dgz_cli.spec.models import HandSpec


def run_episodes(pairs: list[tuple[HandSpec, ObjectModel]], make_policy: Callable[[GraspEnv], object], trials: int,
                 cfg: EnvConfig = EnvConfig(), seed: int = 0, asset_root: str | None = None, threads: int = 2,
                 progress: Callable[[int, int], None] | None = None) -> list[dict]:
    """Run ``trials`` episodes on every pair; ``make_policy(env)`` returns an object with
    ``act(obs) -> action`` and ``reset(mask)``. Records: hand, object, trial, success, return_, r_*."""
    env = GraspEnv(pairs, cfg, seed=seed, asset_root=asset_root, threads=threads)
    policy = make_policy(env)
    obs = env.reset(seed)
    policy.reset(None)
    done_count = np.zeros(env.B, dtype=np.int64)
    records: list[dict] = []
    total = trials * env.B
    while (done_count < trials).any():
        obs, _, _, _, info = env.step(policy.act(obs))
        finished = np.zeros(env.B, bool)
        for b, ep in info["episode"].items():
            finished[b] = True
            if done_count[b] < trials:
                records.append(dict(ep, trial=int(done_count[b])))
            done_count[b] += 1
        if finished.any():
            policy.reset(finished)
            if progress is not None:
                progress(min(total, int(np.minimum(done_count, trials).sum())), total)
    env.close()
    return records


def summarize(records: list[dict]) -> dict:
    """Success rate per hand and per (hand, object)."""
    out: dict[str, dict] = {}
    for r in records:
        h = out.setdefault(r["hand"], {"episodes": 0, "successes": 0, "objects": {}})
        h["episodes"] += 1
        h["successes"] += int(r["success"])
        o = h["objects"].setdefault(r["object"], [0, 0])
        o[0] += int(r["success"])
        o[1] += 1
    for h in out.values():
        h["success_rate"] = h["successes"] / max(1, h["episodes"])
        h["objects"] = {k: {"success_rate": s / n, "trials": n} for k, (s, n) in sorted(h["objects"].items())}
    return out
