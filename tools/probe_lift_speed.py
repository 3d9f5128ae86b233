"""Is *not lifted* the lift's speed? The contract lifts the wrist 0.5 m in `lift_steps` 30 control steps (0.33 m/s,
from rest to full speed in one step). The scripted grasp of `dgz eval --policy scripted --roll clear --thumb-open 0.5
--guidance 0.05 --settle 2` under the same contract but for a slower lift (the same height in more steps), on the nine
objects YCB-45 is lost on and four controls, seed 0. Only the script: a policy's `phase` input would change meaning.
docs/training.md, "Is not lifted the lift's speed".
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_lift_speed.py HANDS [VARIANTS] [SLOTS]"""
import json
import sys

from probe_common import NINE, e13_scripted, probe

from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec

CONTROL = "005_tomato_soup_can,013_apple,006_mustard_bottle,011_banana"
VARIANTS = {"lift 30 steps": 30, "lift 60 steps": 60, "lift 90 steps": 90}  # 0.33, 0.17, 0.11 m/s


def run(spec, lift_steps: int, objects: str, slots: int) -> dict:
    cfg, fields = e13_scripted()
    contract = cfg.contract.model_copy(update=dict(episode=cfg.contract.episode.model_copy(
        update=dict(lift_steps=lift_steps))))
    return probe(spec, contract, None, slots=slots, objects=objects, env=fields | {"settle_s": 2.0})


if __name__ == "__main__":
    hands = sys.argv[1].split(",")
    names = sys.argv[2].split(",") if len(sys.argv) > 2 and sys.argv[2] else list(VARIANTS)
    slots = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    out: dict = {}
    for hand in hands:
        spec = load_spec(resolve_spec(hand))
        for name in names:
            for group, objs in (("nine", NINE), ("control", CONTROL)):
                r = run(spec, VARIANTS[name], objs, slots)
                out.setdefault(hand, {}).setdefault(name, {})[group] = r
                print(hand, name, group, r, flush=True)
    print(json.dumps(out))
