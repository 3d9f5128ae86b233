"""The finger scale (contract action.finger_scale, rad per unit of a finger action: how fast the closing prior
closes) for the closing prior alone (zero residual) under E13's contract (docs/results/e13_train.yaml: Markov
layout, guidance 0.05, close_guide 0.08, thumb start pose 0.5, finger residual 0.5), from the clear roll's start
states, on the ladder's 10 objects × 2 slots × 1 episode per hand.
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_finger_scale.py [HANDS] [VARIANTS]"""
from pathlib import Path

import yaml
from probe_common import main, probe, zero

from dgz_cli.rl.config import TrainConfig, env_config

HANDS = "allegro,shadow,schunk_svh,ability,leap,inspire,revo2,barrett"
E13 = env_config(TrainConfig(**yaml.safe_load((Path(__file__).parents[1] / "docs/results/e13_train.yaml").read_text())))
VARIANTS = {f"scale {s}": s for s in (0.015, 0.03)}


def run(spec, scale: float) -> dict:
    contract = E13.contract.model_copy(update=dict(action=E13.contract.action.model_copy(update=dict(finger_scale=scale))))
    return probe(spec, contract, zero, slots=2, env={"roll": E13.roll})


if __name__ == "__main__":
    main(VARIANTS, run, HANDS)
