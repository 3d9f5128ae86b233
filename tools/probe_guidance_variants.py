"""The wrist guidance alone, in variants (issue 11, docs/training.md after E9): the closing prior with a zero
residual (E6's contract: guidance 0.05, close_guide 0.08, narrow roll, Markov layout) on the ladder's 10 objects x
3 slots, with the guidance (a) as is, (b) scaled by 0 or 0.3 once the prior closes, (c) off inside a 3 or 5 cm dead
band of the guidance error. Prints success and the failed episodes per class of `dgz eval`
(`dgz_cli.sim.evaluate.failure_class`, the protocol's lift height and success fraction).
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_guidance_variants.py HANDS [VARIANTS]"""
import numpy as np
from probe_common import LAYOUT, main, probe, zero

from dgz_cli.spec.contract import ClosingPrior, ControlContract, WristGuidance

# name: (kind, value): "hold_on_close" scales the guidance by value once the prior closes; "deadband" turns it off
# while the guidance error is below value (m)
VARIANTS = {"base": ("none", 0), "hold0": ("hold_on_close", 0.0), "hold.3": ("hold_on_close", 0.3),
            "dead.03": ("deadband", 0.03), "dead.05": ("deadband", 0.05)}


def run(spec, variant):
    contract = ControlContract(observation=LAYOUT, guidance=WristGuidance(gain=0.05),
                               prior=ClosingPrior(enabled=True, close_guide=0.08))
    kind, value = variant

    def patch_guidance(env):
        base = env.guidance

        def guided(glob):
            g = base(glob)
            prior = contract.prior_action(env._nodes, glob, env.closing, env.node_valid)
            closing = prior[:, contract.action.wrist_dim::contract.action.n_prim].any(-1)
            err = np.linalg.norm(glob[:, LAYOUT.global_col("guide")].astype(float) * LAYOUT.target_scale, axis=-1)
            if kind == "hold_on_close":
                g[closing] *= value
            if kind == "deadband":
                g[err < value] = 0.0
            return g

        env.guidance = guided

    return probe(spec, contract, zero, setup=patch_guidance)

if __name__ == "__main__":
    main(VARIANTS, run)
