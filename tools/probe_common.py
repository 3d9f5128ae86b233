"""What the zero-residual probes in tools/ share: the ladder's 10 objects, E6's Markov layout, one episode per
(object, slot) through `dgz eval`'s own loop and summary (`dgz_cli.sim.evaluate.run_episodes`, `summarize`), and
the per-hand command line `HANDS [VARIANTS]`."""
import sys
from collections.abc import Callable

import numpy as np

from dgz_cli.sim.env import GraspEnv
from dgz_cli.sim.evaluate import run_episodes, summarize
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import MARKOV_GLOBAL_BLOCKS, MARKOV_NODE_BLOCKS, ControlContract, ObservationLayout
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.io import load_spec

OBJS = ("004_sugar_box,005_tomato_soup_can,006_mustard_bottle,011_banana,013_apple,017_orange,025_mug,"
        "055_baseball,061_foam_brick,077_rubiks_cube")
LAYOUT = ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS)


def probe(spec, contract: ControlContract, action: Callable[[GraspEnv], np.ndarray], slots: int = 3,
          setup: Callable[[GraspEnv], None] | None = None) -> dict:
    """One episode on each of OBJS × ``slots`` for HandSpec ``spec`` under ``contract`` (narrow roll, seed 0), the
    action each step ``action(env)`` (B, action_dim); ``setup(env)`` may patch the env before its reset.

    Returns the success rate and the count of failed episodes per failure class of `dgz eval`."""
    class Probe:
        def __init__(self, env: GraspEnv) -> None:
            self.env = env
            if setup is not None:
                setup(env)

        def reset(self, mask) -> None:
            pass

        def act(self, obs) -> np.ndarray:
            return action(self.env)

    pairs = [(spec, o) for o in resolve_objects(OBJS)] * slots
    records = run_episodes(pairs, Probe, trials=1, cfg=EnvConfig(contract=contract, roll="narrow"))
    (hand,) = summarize(records, contract.episode.lift_height, contract.episode.success_fraction).values()
    return {"success": round(hand["success_rate"], 3), **hand["failures"]}


def main(variants: dict, run: Callable) -> None:
    """`python tools/probe_X.py HANDS [VARIANTS]`: print `hand variant {success, failures...}` per pair."""
    hands = sys.argv[1].split(",")
    names = sys.argv[2].split(",") if len(sys.argv) > 2 else list(variants)
    for hand in hands:
        spec = load_spec(resolve_spec(hand))
        for name in names:
            print(hand, name, run(spec, variants[name]), flush=True)
