"""The clear start roll's penetration tolerance (EnvConfig.clearance_depth): the guided, thumb-opened scripted grasp
(E0'' of docs/training.md) under roll 'clear' with the palm and forearm allowed this far below the table at the
guidance target, on the ladder's 10 objects × 10 trials per hand.
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_clearance_depth.py HANDS [VARIANTS]"""
from probe_common import LAYOUT, main, probe

from dgz_cli.spec.contract import ControlContract, StartPose, WristGuidance

VARIANTS = {"narrow": ("narrow", 0.0), "clear": ("clear", 0.0), "clear depth.03": ("clear", 0.03)}


def run(spec, variant):
    roll, depth = variant
    contract = ControlContract(observation=LAYOUT, guidance=WristGuidance(gain=0.05), start=StartPose(thumb_open=0.5))
    return probe(spec, contract, None, slots=1, trials=10, env=dict(roll=roll, clearance_depth=depth))


if __name__ == "__main__":
    main(VARIANTS, run)
