"""The closing prior alone (zero residual; E2's rule: gap < 3 cm or from step `close_step`) against the guided
scripted grasp on LEAP and Allegro, 5 YCB objects × 2 slots × 2 episodes (docs/training.md, lever 6).
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_closing_prior.py [HANDS] [VARIANTS]"""
from probe_common import main
from probe_prior_variants import run

from dgz_cli.spec.contract import ClosingPrior

OBJECTS = "025_mug,011_banana,004_sugar_box,013_apple,077_rubiks_cube"
VARIANTS = {"scripted+guid": None,
            **{f"prior {step} {gap}": ClosingPrior(enabled=True, close_step=step, close_gap=gap)
               for step, gap in ((50, 0.03), (80, 0.03), (80, 0.05))}}

if __name__ == "__main__":
    main(VARIANTS, lambda spec, prior: run(spec, prior, objects=OBJECTS, trials=2), "leap,allegro")
