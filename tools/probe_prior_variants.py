"""Closing-prior variants alone (zero residual) against the guided scripted grasp, same start states
(guidance 0.05, narrow roll, Markov layout), on the ladder's 10 objects × 2 slots × 1 episode per hand.
docs/training.md, lever 6. Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_prior_variants.py [HANDS]"""
from probe_common import LAYOUT, main, probe, zero

from dgz_cli.spec.contract import ActionLayout, ClosingPrior, ControlContract, WristGuidance

HANDS = "allegro,shadow,schunk_svh,ability,leap,inspire"
VARIANTS = {  # None: the scripted grasp (latch + stall) instead of a prior
    "scripted": None,
    "prior step50": ClosingPrior(enabled=True),
    "prior step50 guide.06": ClosingPrior(enabled=True, close_guide=0.06),
    "prior step50 guide.08": ClosingPrior(enabled=True, close_guide=0.08),
    "prior step40 guide.08": ClosingPrior(enabled=True, close_step=40, close_guide=0.08),
    "prior step40": ClosingPrior(enabled=True, close_step=40),
}


def run(spec, prior: ClosingPrior | None, action: ActionLayout | None = None, objects: str | None = None,
        trials: int = 1) -> dict:
    """Success and failure classes of the scripted grasp (``prior`` None) or of ``prior`` on a zero residual."""
    contract = ControlContract(observation=LAYOUT, guidance=WristGuidance(gain=0.05), prior=prior or ClosingPrior(),
                               action=action or ActionLayout())
    return probe(spec, contract, None if prior is None else zero, slots=2, trials=trials,
                 **({"objects": objects} if objects else {}))


if __name__ == "__main__":
    main(VARIANTS, run, HANDS)
