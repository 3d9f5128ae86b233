"""Does the approach's tilt decide the thin objects? (issue 11, docs/training.md after "Why the fingers do not get under
a knife"). The scripted grasp under E13's settings (`dgz eval --policy scripted --roll clear --thumb-open 0.5
--guidance 0.05`) from objects settled 2 s, on the nine objects YCB-45 is lost on × 3 slots × 2 trials per hand,
with the start's approach tilted at most CONE rad from vertical (the env's ``approach_cone``; 0.5 is the protocol's,
0 straight down). Prints one JSON line per (hand, cone): success and failure classes.
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_approach_cone.py HANDS CONES"""
import json
import sys

from probe_common import NINE, e13_scripted, probe

from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec


def main(hands: str, cones: str) -> None:
    cfg, env = e13_scripted()
    for hand in hands.split(","):
        spec = load_spec(resolve_spec(hand))
        for cone in (float(c) for c in cones.split(",")):
            r = probe(spec, cfg.contract, None, slots=3, objects=NINE, trials=2,
                      env=env | {"approach_cone": cone, "settle_s": 2.0})
            print(hand, cone, json.dumps(r), flush=True)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(f"usage: {sys.argv[0]} HANDS CONES   (e.g. allegro,inspire 0.5,0)")
    main(sys.argv[1], sys.argv[2])
