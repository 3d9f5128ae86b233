"""A hooked approach (issue 11, docs/training.md after E16): the scripted grasp under E13's settings (guidance 0.05,
clear roll, thumb half open; `dgz eval --policy scripted --roll clear --thumb-open 0.5 --guidance 0.05`), 5 trials
per object, where during the first K control steps of the approach every FLEX-active finger node (not the wrist) also
gets a FLEX command of `amount` (normalized; one unit moves a joint by the contract's finger_scale, 0.015 rad, per
step), so the fingers curl into a hook before the tips reach the table and the palm can come lower; the script's own
closing then takes over as before. Objects: the nine YCB-45 is lost on (default) or the ladder's 10 (`--ten`).
Prints success and the failed episodes per class of `dgz eval` (`dgz_cli.sim.evaluate.failure_class`).
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_hook.py HANDS [VARIANTS] [--ten]"""
import sys

import numpy as np
from probe_common import NINE, OBJS, e13_scripted, main, probe

from dgz_cli.sim.scripted import ScriptedGrasp
from dgz_cli.spec.models import NODE_TYPES

# name: (K steps, amount)
VARIANTS = {"base": (0, 0.0), "hook20": (20, 1.0), "hook40": (40, 1.0), "hook40h": (40, 0.5)}
TEN = "--ten" in sys.argv
if TEN:
    sys.argv.remove("--ten")


def run(spec, variant):
    steps, amount = variant
    cfg, fields = e13_scripted()
    act = cfg.contract.action
    wrist = NODE_TYPES.index("wrist")

    class Hooked(ScriptedGrasp):
        def act(self, obs):
            action = super().act(obs)
            early = (self.env.t < steps) & ~self.closing
            lay = self.contract.observation
            is_wrist = obs["nodes"][:, :, lay.node_col("node_type").start + wrist] > 0
            flex = np.zeros(obs["mask"].shape, dtype=np.float32)
            flex[:, :, 0] = amount * obs["mask"][:, :, 0] * ~is_wrist
            action[:, act.wrist_dim:] += np.where(early[:, None], flex.reshape(len(flex), -1), 0.0)
            return action

    def policy(env):
        grasp = Hooked.for_env(env)
        grasp.env = env
        return grasp

    return probe(spec, cfg.contract, None, slots=1, objects=OBJS if TEN else NINE, trials=5,
                 env=fields, make_policy=policy)


if __name__ == "__main__":
    main(VARIANTS, run)
