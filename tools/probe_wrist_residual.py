"""What a policy's wrist residual does, per hand: during the grasp phase, the mean per-step wrist translation
(mm, palm axes f/l/n) the policy's residual commands (its clipped wrist action × ``wrist_residual`` ×
``wrist_scale``) next to the guidance's, the residual's mean size and its cosine to the guidance, the open
hand's thumb tip and mean other fingertip (mm, palm frame, as the guidance's grasp point is measured), and the
success rate, on the ladder's 10 objects × ``slots`` starts, one trial each, in the checkpoint's own env.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_wrist_residual.py CHECKPOINT HANDS [SLOTS]`"""
import json
import sys

import numpy as np

from dgz_cli.rl.checkpoint import LoadedPolicy
from dgz_cli.sim.evaluate import run_episodes, summarize
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec
from probe_common import OBJS, open_hand_tips


class Recorder:
    """The checkpoint's policy; each grasp-phase step adds its wrist residual and the guidance (B, 3) m."""

    def __init__(self, env, policy: LoadedPolicy) -> None:
        self.env, self.policy = env, policy
        self.residual, self.guide, self.steps = np.zeros(3), np.zeros(3), 0
        self.size, self.cos = [], []

    def reset(self, mask) -> None:
        self.policy.reset(mask)

    def act(self, obs):
        a = self.policy.act(obs)
        act = self.env.cfg.contract.action
        grasp = self.env.t < self.env.cfg.contract.episode.grasp_steps
        r = (np.clip(a[:, :3], -1, 1) * act.wrist_residual * act.wrist_scale)[grasp]
        g = self.env.guidance(obs["global"], obs["nodes"])[grasp, :3]
        self.residual += r.sum(0)
        self.guide += g.sum(0)
        self.steps += len(r)
        size_r = np.linalg.norm(r, axis=-1)
        self.size.extend(size_r)
        ng = np.linalg.norm(g, axis=-1) * size_r
        ok = ng > 1e-12
        self.cos.extend((r * g).sum(-1)[ok] / ng[ok])
        return a


def main() -> None:
    if len(sys.argv) < 3:
        sys.exit(__doc__.splitlines()[-1])
    policy = LoadedPolicy(sys.argv[1])
    slots = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    out = {}
    for hand in sys.argv[2].split(","):
        spec = load_spec(resolve_spec(hand))
        pairs = [(spec, o) for o in resolve_objects(OBJS)] * slots
        holder = {}

        def make(env):
            holder["r"] = Recorder(env, policy)
            return holder["r"]

        records = run_episodes(pairs, make, trials=1, cfg=policy.meta.env)
        (summary,) = summarize(records).values()
        r = holder["r"]
        thumb, others = open_hand_tips(spec)
        out[hand] = dict(success=round(summary["success_rate"], 3),
                         residual_mm_per_step=[round(1e3 * v / r.steps, 3) for v in r.residual],
                         guidance_mm_per_step=[round(1e3 * v / r.steps, 3) for v in r.guide],
                         residual_size_mm=round(1e3 * float(np.mean(r.size)), 3),
                         cos_to_guidance=round(float(np.mean(r.cos)), 3) if r.cos else None,
                         thumb_tip_mm=[round(1e3 * v) for v in thumb], other_tips_mm=[round(1e3 * v) for v in others],
                         failures=summary["failures"])
        print(hand, json.dumps(out[hand]), flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
