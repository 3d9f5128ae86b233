"""The wrist guidance alone, in variants (issue 11, docs/training.md after E9): the closing prior with a zero
residual (E6's contract: guidance 0.05, close_guide 0.08, narrow roll, Markov layout) on the ladder's 10 objects x
3 slots, with the guidance (a) as is, (b) scaled by 0 or 0.3 once the prior closes, (c) off inside a 3 or 5 cm dead
band of the guidance error. Prints success and the failed episodes per class of `dgz eval`
(`dgz_cli.sim.evaluate.failure_class`, the protocol's lift height and success fraction).
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_guidance_variants.py HANDS [VARIANTS]"""
import json, sys
import numpy as np
from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.evaluate import FAILURE_CLASSES, failure_class
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import (MARKOV_GLOBAL_BLOCKS, MARKOV_NODE_BLOCKS, ClosingPrior, ControlContract,
                                   ObservationLayout, WristGuidance)
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.io import load_spec
OBJS = ("004_sugar_box,005_tomato_soup_can,006_mustard_bottle,011_banana,013_apple,017_orange,025_mug,"
        "055_baseball,061_foam_brick,077_rubiks_cube")
LAYOUT = ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS)

def run(spec, variant, slots=3):
    contract = ControlContract(observation=LAYOUT, guidance=WristGuidance(gain=0.05),
                               prior=ClosingPrior(enabled=True, close_guide=0.08))
    env = GraspEnv([(spec, o) for o in resolve_objects(OBJS)] * slots, EnvConfig(contract=contract, roll="narrow"), threads=2)
    base = env.guidance
    def guided(glob):
        g = base(glob)
        c = env.cfg.contract
        pa = c.prior_action(env._nodes, glob, env.mask, env.node_valid)
        closing = pa[:, c.action.wrist_dim::c.action.n_prim].any(-1)
        err = np.linalg.norm(glob[:, LAYOUT.global_col("guide")].astype(float) * LAYOUT.target_scale, axis=-1)
        kind, x = variant
        if kind == "hold_on_close": g[closing] *= x
        if kind == "deadband": g[err < x] = 0.0
        return g
    env.guidance = guided
    obs = env.reset(0)
    done = {}
    while len(done) < env.B:
        obs, _, _, _, info = env.step(np.zeros((env.B, env.action_dim)))
        for b, e in info["episode"].items():
            done.setdefault(b, e)
    env.close()
    ep = env.cfg.contract.episode
    cls = dict.fromkeys(FAILURE_CLASSES, 0)
    for e in done.values():
        why = failure_class(e, ep.lift_height, ep.success_fraction)
        if why is not None:
            cls[why] += 1
    return {"success": float(np.mean([e["success"] for e in done.values()])), **cls}

V = {"base": ("none", 0), "hold0": ("hold_on_close", 0.0), "hold.3": ("hold_on_close", 0.3),
     "dead.03": ("deadband", 0.03), "dead.05": ("deadband", 0.05)}
hands = sys.argv[1].split(",")
names = sys.argv[2].split(",") if len(sys.argv) > 2 else list(V)
for hand in hands:
    spec = load_spec(resolve_spec(hand))
    for n in names:
        print(hand, n, run(spec, V[n]), flush=True)
