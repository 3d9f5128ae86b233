"""Closing-prior variants alone (zero residual) against the guided scripted grasp, same start states
(guidance 0.05, narrow roll, Markov layout), on the ladder's 10 objects × 2 slots × 1 episode per hand.
docs/training.md, lever 6. Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_prior_variants.py [HANDS]"""

import json
import sys

import numpy as np

from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.sim.scripted import ScriptedGrasp
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import (MARKOV_GLOBAL_BLOCKS, MARKOV_NODE_BLOCKS, ActionLayout, ClosingPrior, ControlContract,
                                   ObservationLayout, WristGuidance)
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.io import load_spec

OBJS = ("004_sugar_box,005_tomato_soup_can,006_mustard_bottle,011_banana,013_apple,017_orange,025_mug,"
        "055_baseball,061_foam_brick,077_rubiks_cube")
LAYOUT = ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS)
GUIDE = WristGuidance(gain=0.05)
VARIANTS = {
    "scripted": None,
    "prior step50": ClosingPrior(enabled=True),
    "prior step50 guide.06": ClosingPrior(enabled=True, close_guide=0.06),
    "prior step50 guide.08": ClosingPrior(enabled=True, close_guide=0.08),
    "prior step40 guide.08": ClosingPrior(enabled=True, close_step=40, close_guide=0.08),
    "prior step40": ClosingPrior(enabled=True, close_step=40),
}


def run(spec, prior: ClosingPrior | None, action: ActionLayout | None = None, threads: int = 2) -> dict:
    contract = ControlContract(observation=LAYOUT, guidance=GUIDE, prior=prior or ClosingPrior(),
                               action=action or ActionLayout())
    env = GraspEnv([(spec, o) for o in resolve_objects(OBJS)] * 2, EnvConfig(contract=contract, roll="narrow"),
                   threads=threads)
    obs = env.reset(0)
    pol = ScriptedGrasp(env.N, env.grasp_offset, contract) if prior is None else None
    done = {}
    while len(done) < env.B:
        a = pol.act(obs) if pol else np.zeros((env.B, env.action_dim))
        obs, _, _, _, info = env.step(a)
        for b, e in info["episode"].items():
            done.setdefault(b, bool(e["success"]))
        if pol and info["episode"]:
            m = np.zeros(env.B, bool)
            m[list(info["episode"])] = True
            pol.reset(m)
    env.close()
    return {"success": float(np.mean(list(done.values()))), "episodes": len(done)}


if __name__ == "__main__":
    hands = sys.argv[1].split(",") if len(sys.argv) > 1 else ["allegro", "shadow", "schunk_svh", "ability", "leap", "inspire"]
    out = {}
    for hand in hands:
        spec = load_spec(resolve_spec(hand))
        for name, prior in VARIANTS.items():
            out.setdefault(hand, {})[name] = run(spec, prior)
            print(hand, name, out[hand][name], flush=True)
    print(json.dumps(out))
