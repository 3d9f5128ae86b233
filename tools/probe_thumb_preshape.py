"""Thumb pre-shaping under the closing prior (issue 11, docs/training.md after E10): E6's contract (guidance 0.05,
close_guide 0.08, narrow roll, Markov layout) with a zero residual on the ladder's 10 objects x 3 slots, and during
the first K steps of the approach an extra action on the thumb's non-FLEX primitives, in the sign conventions of
docs (+ROT turns the thumb pad toward the fingers; +ABD opens the thumb away from the index). A unit action moves a
joint by the contract's finger_scale per step, so K steps move it by K x 0.015 rad, within its limits. The start.F
variants instead start the hand in the contract's StartPose(thumb_open=F) (startFrot: its ABD and ROT joints).
Prints success and the failed episodes per class of `dgz eval` (`dgz_cli.sim.evaluate.failure_class`).
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_thumb_preshape.py HANDS [VARIANTS]"""
import numpy as np
from probe_common import LAYOUT, main, probe

from dgz_cli.spec.contract import ClosingPrior, ControlContract, StartPose, WristGuidance

ABD, ROT = 1, 2
# name: ({primitive: unit action on every thumb node}, K steps)
VARIANTS = {"base": ({}, 0), "rot+": ({ROT: 1.0}, 35), "abd-": ({ABD: -1.0}, 35), "abd+": ({ABD: 1.0}, 35),
            "rot+abd-": ({ROT: 1.0, ABD: -1.0}, 35), "abd+20": ({ABD: 1.0}, 20), "abd+70": ({ABD: 1.0}, 70),
            "rot+abd+": ({ROT: 1.0, ABD: 1.0}, 35), "start.5": ({}, 0, 0.5), "start1": ({}, 0, 1.0),
            "start1rot": ({}, 0, 1.0, ("ABD", "ROT")), "start.5rot": ({}, 0, 0.5, ("ABD", "ROT"))}


def run(spec, variant):
    prims, steps, *opening = variant
    start = StartPose(thumb_open=opening[0], thumb_primitives=opening[1] if len(opening) > 1 else ("ABD",)) \
        if opening else StartPose()
    contract = ControlContract(observation=LAYOUT, guidance=WristGuidance(gain=0.05),
                               prior=ClosingPrior(enabled=True, close_guide=0.08), start=start)
    act = contract.action
    preshape = np.zeros(act.dim(len(spec.nodes)))  # a one-hand env's action_dim
    for i, node in enumerate(spec.nodes):
        if node.finger == "thumb":
            for p, value in prims.items():
                preshape[act.wrist_dim + i * act.n_prim + p] = value
    return probe(spec, contract, lambda e: np.where((e.t < steps)[:, None], preshape[None, :], 0.0))


if __name__ == "__main__":
    main(VARIANTS, run)
