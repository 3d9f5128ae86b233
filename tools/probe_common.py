"""What the zero-residual probes in tools/ share: the ladder's 10 objects, E6's Markov layout, one episode per env
run to its end with `dgz eval`'s failure classes, and the per-hand command line `HANDS [VARIANTS]`."""
import sys
from collections.abc import Callable

import numpy as np

from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.evaluate import FAILURE_CLASSES, failure_class
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import MARKOV_GLOBAL_BLOCKS, MARKOV_NODE_BLOCKS, ObservationLayout
from dgz_cli.spec.io import load_spec

OBJS = ("004_sugar_box,005_tomato_soup_can,006_mustard_bottle,011_banana,013_apple,017_orange,025_mug,"
        "055_baseball,061_foam_brick,077_rubiks_cube")
LAYOUT = ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS)


def run_episodes(env: GraspEnv, action: Callable[[GraspEnv], np.ndarray], seed: int = 0) -> dict:
    """Reset `env`, step it with `action(env)` (B, action_dim) until every env has finished one episode, close it.

    Returns the success rate over the B first episodes and the count of failed episodes per failure class."""
    env.reset(seed)
    done: dict[int, dict] = {}
    while len(done) < env.B:
        _, _, _, _, info = env.step(action(env))
        for b, e in info["episode"].items():
            done.setdefault(b, e)
    env.close()
    ep = env.cfg.contract.episode
    counts = dict.fromkeys(FAILURE_CLASSES, 0)
    for e in done.values():
        why = failure_class(e, ep.lift_height, ep.success_fraction)
        if why is not None:
            counts[why] += 1
    return {"success": round(float(np.mean([e["success"] for e in done.values()])), 3), **counts}


def main(variants: dict, run: Callable) -> None:
    """`python tools/probe_X.py HANDS [VARIANTS]`: print `hand variant {success, failures...}` per pair."""
    hands = sys.argv[1].split(",")
    names = sys.argv[2].split(",") if len(sys.argv) > 2 else list(variants)
    for hand in hands:
        spec = load_spec(resolve_spec(hand))
        for name in names:
            print(hand, name, run(spec, variants[name]), flush=True)
