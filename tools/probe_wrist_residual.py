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
from dgz_cli.spec.kinematics import HandKinematics
from probe_common import OBJS


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
        r = np.clip(a[:, :3], -1, 1) * act.wrist_residual * act.wrist_scale
        g = self.env.guidance(obs["global"])[:, :3]
        self.residual += r[grasp].sum(0)
        self.guide += g[grasp].sum(0)
        self.steps += int(grasp.sum())
        self.size.extend(np.linalg.norm(r[grasp], axis=-1))
        ng = np.linalg.norm(g[grasp], axis=-1) * np.linalg.norm(r[grasp], axis=-1)
        ok = ng > 1e-12
        self.cos.extend(((r[grasp] * g[grasp]).sum(-1)[ok] / ng[ok]))
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
        kin = HandKinematics.for_spec(spec)
        anchors = kin.anchors_palm(kin.rest)  # (N, 3) m, the flat open hand
        tip = [n.type == "fingertip" for n in spec.nodes]
        thumb = anchors[[t and n.finger == "thumb" for t, n in zip(tip, spec.nodes)]].mean(0)
        others = anchors[[t and n.finger != "thumb" for t, n in zip(tip, spec.nodes)]].mean(0)
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
