"""Is *not lifted* the lift's speed? The contract lifts the wrist 0.5 m in `lift_steps` 30 control steps (0.33 m/s,
from rest to full speed in one step). The scripted grasp of `dgz eval --policy scripted --roll clear --thumb-open 0.5
--guidance 0.05 --settle 2` under the same contract but for a slower lift (the same height in more steps), on the nine
objects YCB-45 is lost on and four controls, seed 0. Only the script: a policy's `phase` input would change meaning.
docs/training.md, "Is not lifted the lift's speed".
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_lift_speed.py HANDS [VARIANTS] [SLOTS]"""
from probe_common import CONTROL, NINE, e13_scripted, main_grouped, probe

VARIANTS = {"lift 30 steps": 30, "lift 60 steps": 60, "lift 90 steps": 90}  # 0.33, 0.17, 0.11 m/s


def run(spec, lift_steps: int, objects: str, slots: int) -> dict:
    cfg, fields = e13_scripted()
    contract = cfg.contract.model_copy(update=dict(episode=cfg.contract.episode.model_copy(
        update=dict(lift_steps=lift_steps))))
    return probe(spec, contract, None, slots=slots, objects=objects, env=fields | {"settle_s": 2.0})


if __name__ == "__main__":
    main_grouped(VARIANTS, run, {"nine": NINE, "control": CONTROL}, default_slots=3)
