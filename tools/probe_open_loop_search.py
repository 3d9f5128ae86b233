"""Is there any grasp of a lost object that this control contract can express? A cross-entropy search over
open-loop residuals, per (hand, object), from the env of a checkpoint (its protocol, start states and closing
prior), with the finger and wrist residual factors at full authority (so a finger can be held back) and the wrist's
translation an aim shift of up to AIM m (default 0.08).

A candidate θ (15 numbers for a four-finger hand) is constant over the episode: the aim shift (3, ±1 → ±AIM m on
the palm's axes), a closing delay (one number in [0, 1] → 0–100 control steps during which every FLEX action is −1,
i.e. the prior's closing is cancelled), a wrist rotation rate (3, ±1 → ±0.01 rad per step about the palm's axes,
times ROT, for the first ROT_STEPS steps: up to 0.6 rad of tilt), and per finger a FLEX action in [−1, 0] once the
delay is over (0: close as the prior does, −1: hold the finger) and an ABD action in [−1, 1] throughout. Every
candidate runs on the same STARTS start states (seed SEED, one episode each); its score is the success rate plus
0.1 × the mean max rise / 0.5 m (a tie-breaker toward lifting). The search keeps the ELITE best of POP per
generation.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_open_loop_search.py CHECKPOINT HAND OBJECT
[GENERATIONS=8] [STARTS=8] [SEED=0] [AIM=0.08] [ROT=1]` prints each generation's best and mean, then
one JSON line: the prior alone and the best candidate on the search's starts, and both on STARTS other starts (seed
SEED + 1000). With STARTS 1 and SEED 0, 1, ... it asks, start by start, whether any such residual lifts the object
from that start. A probe of what the contract can express, not a policy."""
import json
import sys
from pathlib import Path

import numpy as np

from dgz_cli.rl.checkpoint import LoadedPolicy
from dgz_cli.sim.evaluate import make_env
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec
from dgz_cli.spec.models import PRIMITIVES

AIM, POP, ELITE, DELAY_STEPS, ROT_STEPS = 0.08, 20, 5, 100, 60
FINGER0 = 7  # θ: aim (3), closing delay (1), rotation rate (3), then (FLEX, ABD) per finger


class Candidate:
    """The open-loop residual of one θ: ``action(t)`` (B, action_dim) for the control steps t (B,) of a hand
    whose fingers are ``finger_masks`` (per finger in θ's order, which of its N nodes (N,) bool belong to it)."""

    def __init__(self, theta: np.ndarray, finger_masks: list[np.ndarray], act, rot: float = 1.0) -> None:
        n_prim, flex, abd = act.n_prim, PRIMITIVES.index("FLEX"), PRIMITIVES.index("ABD")
        N = len(finger_masks[0])
        self.theta, self.act, self.N = theta, act, N
        self.delay = int(round(np.clip(theta[3], 0, 1) * DELAY_STEPS))
        closing = np.zeros((N, n_prim))  # the finger actions once the delay is over; before it FLEX is -1
        for i, on in enumerate(finger_masks):
            closing[on, abd] = np.clip(theta[FINGER0 + 2 * i + 1], -1, 1)
            closing[on, flex] = np.clip(theta[FINGER0 + 2 * i], -1, 0)
        held = closing.copy()
        held[np.any(finger_masks, axis=0), flex] = -1.0
        self.closing, self.held = closing.reshape(-1), held.reshape(-1)
        self.rotation = rot * np.clip(theta[4:7], -1, 1)

    def action(self, t: np.ndarray) -> np.ndarray:
        a = np.zeros((len(t), self.act.dim(self.N)))
        a[:, :3] = np.clip(self.theta[:3], -1, 1)
        a[:, 3:6] = np.where(t[:, None] < ROT_STEPS, self.rotation, 0.0)
        a[:, self.act.wrist_dim:] = np.where(t[:, None] < self.delay, self.held, self.closing)
        return a


def finger_masks_of(spec) -> tuple[list[str], list[np.ndarray]]:
    """The hand's finger names (sorted) and per finger which of its nodes (N,) bool belong to it."""
    node_finger = np.array([(n.finger or "") if n.type != "wrist" else "" for n in spec.nodes], dtype=object)
    fingers = sorted({f for f in node_finger if f})
    return fingers, [node_finger == f for f in fingers]


def episode_scores(env, theta: np.ndarray, finger_masks: list[np.ndarray], seed: int,
                   rot: float = 1.0) -> tuple[float, float]:
    """(success rate, mean max rise m) of one candidate θ over every slot of ``env`` (one episode each)."""
    candidate = Candidate(theta, finger_masks, env.cfg.contract.action, rot)
    env.reset(seed)
    B = env.B
    done, success, rise = np.zeros(B, bool), np.zeros(B), np.zeros(B)
    while not done.all():
        _, _, _, _, info = env.step(candidate.action(env.t))
        for b, ep in info["episode"].items():
            if not done[b]:
                done[b], success[b], rise[b] = True, ep["success"], ep["max_rise"]
    return float(success.mean()), float(rise.mean())


def search_lines(logs: list[str]) -> list[dict]:
    """The JSON result lines of this probe's logs (and of ``tools/pick_pair_residuals.py``'s), in order."""
    return [json.loads(x) for log in logs for x in Path(log).read_text().splitlines() if x.startswith("{")]


def lifted_per_start(line: dict) -> bool:
    """Whether a result line is a per-start search (``starts`` 1) at the default aim range that lifted the object."""
    return line["starts"] == 1 and line["best"] >= 1.0 and line.get("aim", AIM) == AIM


def search_contract(contract, aim: float = AIM):
    """The contract the search commands in: the checkpoint's, with the residual factors at full authority and
    the translation an aim shift of up to ``aim`` m."""
    return contract.model_copy(update=dict(
        action=contract.action.model_copy(update=dict(finger_residual=1.0, wrist_residual=1.0)),
        guidance=contract.guidance.model_copy(update=dict(aim_residual=aim))))


def main(checkpoint: str, hand: str, obj: str, generations: int = 8, starts: int = 8, seed: int = 0,
         aim: float = AIM, rot: float = 1.0) -> None:
    meta = LoadedPolicy(checkpoint).meta
    cfg = meta.env.model_copy(update=dict(contract=search_contract(meta.contract, aim)))
    spec = load_spec(resolve_spec(hand))
    (model,) = resolve_objects(obj)
    env = make_env([(spec, model)] * starts, cfg, seed=seed)
    fingers, masks = finger_masks_of(spec)
    rng = np.random.default_rng(0)
    dim = FINGER0 + 2 * len(fingers)
    mean, std = np.zeros(dim), np.full(dim, 0.5)
    best = (-1.0, None, 0.0)
    zero = episode_scores(env, mean, masks, seed, rot)
    print(f"{hand} {obj}: zero residual (the prior alone) success {zero[0]:.3f} rise {zero[1]:.3f}", flush=True)
    for g in range(generations):
        cands = mean + std * rng.standard_normal((POP, dim))
        cands[0] = mean
        scored = []
        for c in cands:
            s, r = episode_scores(env, c, masks, seed, rot)
            scored.append((s + 0.1 * min(r / 0.5, 1.0), s, c))
            if s > best[0] or (s == best[0] and r > best[2]):
                best = (s, c.copy(), r)
        scored.sort(key=lambda x: -x[0])
        elite = np.array([c for _, _, c in scored[:ELITE]])
        mean, std = elite.mean(0), np.maximum(elite.std(0), 0.05)
        print(f"gen {g + 1}: best success {scored[0][1]:.3f} mean {np.mean([s for _, s, _ in scored]):.3f} "
              f"overall best {best[0]:.3f}", flush=True)
    fresh = episode_scores(env, best[1], masks, seed + 1000, rot)
    zero_fresh = episode_scores(env, np.zeros(dim), masks, seed + 1000, rot)
    env.close()
    print(json.dumps(dict(hand=hand, object=obj, starts=starts, seed=seed, generations=generations, aim=aim, rot=rot,
                          fingers=fingers,
                          zero=zero[0], best=best[0], best_theta=[round(float(x), 3) for x in best[1]],
                          fresh_best=fresh[0], fresh_zero=zero_fresh[0])), flush=True)


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], sys.argv[3], *(int(x) for x in sys.argv[4:7]), *(float(x) for x in sys.argv[7:9]))
