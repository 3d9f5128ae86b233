"""Evaluation protocol: every (hand, object) pair × trials episodes, success per episode.

Slots are filled with (hand, object) pairs; each slot runs ``trials`` consecutive episodes with
its own seeded randomization (hand pose, object orientation). Returns per-episode records.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.hardware_view import HardwareView
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import ObjectModel
from dgz_cli.spec.models import HandSpec


def run_episodes(pairs: list[tuple[HandSpec, ObjectModel]], make_policy: Callable[[GraspEnv], object], trials: int,
                 cfg: EnvConfig = EnvConfig(), seed: int = 0, asset_root: str | None = None, threads: int = 2,
                 progress: Callable[[int, int], None] | None = None, view: HardwareView | None = None) -> list[dict]:
    """Run ``trials`` episodes on every pair; ``make_policy(env)`` returns an object with
    ``act(obs) -> action`` and ``reset(mask)``. Records: hand, object, trial, success, return_, r_*.
    ``view``: the hardware perturbations the policy observes under (a distilled student's; None = none)."""
    env = make_env(pairs, cfg, seed=seed, asset_root=asset_root, threads=threads, view=view)
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


def make_env(pairs: list[tuple[HandSpec, ObjectModel]], cfg: EnvConfig, *, view: HardwareView | None = None,
             **kwargs) -> GraspEnv:
    """A :class:`GraspEnv`, or under an active hardware ``view`` a
    :class:`~dgz_cli.sim.hardware.HardwareViewEnv` (the observation a real hand and camera give). Evaluation
    and deploy run the full protocol: a training-only ``early_stop`` is turned off."""
    cfg = cfg.model_copy(update=dict(early_stop=False)) if cfg.early_stop else cfg
    if view is not None and view.active:
        from dgz_cli.sim.hardware import HardwareViewEnv

        return HardwareViewEnv(pairs, cfg, view, **kwargs)
    return GraspEnv(pairs, cfg, **kwargs)


FAILURE_CLASSES = ("never touched", "pushed away", "not lifted", "dropped during hold", "unstable")
PUSHED = 0.05  # m: an object displaced this much during the grasp phase was pushed, not grasped
GRASPXL_RISE = 0.1  # m: GraspXL's success criterion (rise at the end of the lift), a secondary column


def failure_class(record: dict, lift_height: float, success_fraction: float) -> str | None:
    """Why an episode failed (None if it succeeded): the paper's failure-case analysis, from the episode
    record of :class:`~dgz_cli.sim.env.GraspEnv`. Checked in this order: unstable (MuJoCo), never touched
    (no hand-object contact), pushed away (the object moved > 5 cm during the grasp phase, or the episode
    ended on the push limit) and not lifted (it did not follow the lift to success_fraction × lift_height),
    dropped during hold (it was up at the end of the lift but fell during the hold)."""
    if record["success"]:
        return None
    if record["unstable"]:
        return "unstable"
    if not record["touched"]:
        return "never touched"
    if record["rise_lift_end"] < success_fraction * lift_height:
        return "pushed away" if record.get("pushed") or record["max_push"] > PUSHED else "not lifted"
    return "dropped during hold"


def summarize(records: list[dict], lift_height: float = 0.5, success_fraction: float = 0.8) -> dict:
    """Success rate per hand and per (hand, object), the failure classes of the failed episodes, and the
    GraspXL criterion (rise ≥ 0.1 m at the end of the lift) as a secondary rate."""
    out: dict[str, dict] = {}
    for r in records:
        h = out.setdefault(r["hand"], {"episodes": 0, "successes": 0, "graspxl": 0, "objects": {},
                                       "failures": dict.fromkeys(FAILURE_CLASSES, 0)})
        h["episodes"] += 1
        h["successes"] += int(r["success"])
        h["graspxl"] += int(r["rise_lift_end"] >= GRASPXL_RISE)
        o = h["objects"].setdefault(r["object"], {"s": 0, "n": 0, "failures": dict.fromkeys(FAILURE_CLASSES, 0)})
        o["s"] += int(r["success"])
        o["n"] += 1
        why = failure_class(r, lift_height, success_fraction)
        if why is not None:
            h["failures"][why] += 1
            o["failures"][why] += 1
    for h in out.values():
        h["success_rate"] = h["successes"] / max(1, h["episodes"])
        h["graspxl_success_rate"] = h.pop("graspxl") / max(1, h["episodes"])
        h["objects"] = {k: {"success_rate": o["s"] / o["n"], "trials": o["n"], "failures": o["failures"]}
                        for k, o in sorted(h["objects"].items())}
    return out
