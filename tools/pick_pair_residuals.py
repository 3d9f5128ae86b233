"""One open-loop residual per (hand, object) pair, chosen for lifting from many starts (issue 11, the rung after
E47): of the per-start residuals a ``tools/probe_open_loop_search.py`` log found (lines with ``starts`` 1 and
``best`` 1.0, at most MAX_CANDIDATES per pair, lowest seeds first), the one that lifts from the most of PICK
starts (one PICK-slot env, seed PICK_SEED) is kept, and it and the prior alone are then run from HELDOUT other
starts (seed HELDOUT_SEED): the out-of-sample rate of the choice, and the starts ``tools/bc_searched.py`` replays
it from as demonstrations. Everything runs in the search's contract and the checkpoint's env.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/pick_pair_residuals.py CHECKPOINT OUT.jsonl SEARCH_LOG...`
(from the repo root; logs of any pairs, grouped by hand and object; logs at another aim range than the default are
skipped) appends one JSON line per pair to OUT.jsonl as it goes and prints a summary."""
import json
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from probe_open_loop_search import (AIM, episode_scores, finger_masks_of, lifted_per_start, search_contract,
                                    search_lines)

from dgz_cli.rl.checkpoint import LoadedPolicy
from dgz_cli.sim.evaluate import make_env
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec

PICK, PICK_SEED, HELDOUT, HELDOUT_SEED, MAX_CANDIDATES = 12, 6000, 16, 7000, 12


def main(checkpoint: str, out: str, logs: list[str]) -> None:
    t0 = time.time()
    meta = LoadedPolicy(checkpoint).meta
    cfg = meta.env.model_copy(update=dict(contract=search_contract(meta.contract, AIM)))
    found = defaultdict(dict)  # (hand, object) -> seed -> line
    for s in filter(lifted_per_start, search_lines(logs)):
        found[(s["hand"], s["object"])].setdefault(s["seed"], s)
    done = set()
    if Path(out).exists():
        done = {(x["hand"], x["object"]) for x in map(json.loads, Path(out).read_text().splitlines())}
    for (hand, obj), by_seed in sorted(found.items()):
        if (hand, obj) in done:
            continue
        candidates = [by_seed[k] for k in sorted(by_seed)[:MAX_CANDIDATES]]
        spec = load_spec(resolve_spec(hand))
        (model,) = resolve_objects(obj)
        masks = finger_masks_of(spec)[1]
        env = make_env([(spec, model)] * PICK, cfg, seed=PICK_SEED)
        rates = [episode_scores(env, np.array(c["best_theta"]), masks, PICK_SEED, c.get("rot", 1.0))[0]
                 for c in candidates]
        env.close()
        best = candidates[int(np.argmax(rates))]
        env = make_env([(spec, model)] * HELDOUT, cfg, seed=HELDOUT_SEED)
        heldout = episode_scores(env, np.array(best["best_theta"]), masks, HELDOUT_SEED, best.get("rot", 1.0))[0]
        prior = episode_scores(env, np.zeros(len(best["best_theta"])), masks, HELDOUT_SEED)[0]
        env.close()
        row = dict(hand=hand, object=obj, candidates=len(candidates), pick_rates=[round(r, 3) for r in rates],
                   residual_seed=best["seed"], best_theta=best["best_theta"], rot=best.get("rot", 1.0), aim=AIM,
                   pick=PICK, pick_seed=PICK_SEED, demo_starts=HELDOUT, demo_seed=HELDOUT_SEED,
                   heldout_best=heldout, heldout_prior=prior)
        with open(out, "a") as f:
            f.write(json.dumps(row) + "\n")
        print(f"{hand:10s} {obj:24s} pick {max(rates):.2f} of {len(candidates)}; held out {heldout:.2f} "
              f"(prior {prior:.2f}); {time.time() - t0:.0f} s", flush=True)
    rows = [json.loads(x) for x in Path(out).read_text().splitlines()]
    print(json.dumps(dict(pairs=len(rows), heldout_best=round(float(np.mean([r["heldout_best"] for r in rows])), 3),
                          heldout_prior=round(float(np.mean([r["heldout_prior"] for r in rows])), 3))))


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
