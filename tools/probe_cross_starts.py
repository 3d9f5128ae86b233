"""Do grasps searched for one start lift the object from the others? Every successful per-start residual of a
``tools/probe_open_loop_search.py`` log (lines with ``starts`` 1 and ``best`` 1.0, one hand and object) is run
from every start of the log, in the search's contract and the checkpoint's env (one episode each).

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_cross_starts.py CHECKPOINT SEARCH_LOG...` (from
the repo root; the logs of one hand and object) prints the matrix (row: the start, column: whose residual; 1 = lifted) and one JSON line: the replays on
their own start, the mean off-diagonal lift rate, how many starts some other start's residual lifts, and the
residual that lifts from the most starts. With `--heldout N` that residual and the prior alone also run from N
other starts (one N-slot env, seed 5000): the out-of-sample check of the choice."""
import json
import sys

import numpy as np

from probe_open_loop_search import episode_scores, finger_masks_of, search_contract, search_lines

from dgz_cli.rl.checkpoint import LoadedPolicy
from dgz_cli.sim.evaluate import make_env
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec


HELDOUT_SEED = 5000


def main(checkpoint: str, logs: list[str], heldout: int = 0) -> None:
    lines = [x for x in search_lines(logs) if x["starts"] == 1]
    hand, obj = lines[0]["hand"], lines[0]["object"]
    meta = LoadedPolicy(checkpoint).meta
    cfg = meta.env.model_copy(update=dict(contract=search_contract(meta.contract, lines[0].get("aim", 0.08))))
    spec = load_spec(resolve_spec(hand))
    (model,) = resolve_objects(obj)
    masks = finger_masks_of(spec)[1]
    found = [x for x in lines if x["best"] >= 1.0]
    seeds = [x["seed"] for x in lines]
    lifted = np.zeros((len(seeds), len(found)))
    for i, seed in enumerate(seeds):
        env = make_env([(spec, model)], cfg, seed=seed)
        for j, x in enumerate(found):
            lifted[i, j] = episode_scores(env, np.array(x["best_theta"]), masks, seed, x.get("rot", 1.0))[0]
        env.close()
        print(f"start {seed:3d}: " + "".join("1" if v else "." for v in lifted[i]), flush=True)
    own = [lifted[seeds.index(x["seed"]), j] for j, x in enumerate(found)]
    other = np.array([[x["seed"] != s for x in found] for s in seeds])  # (starts, residuals): not its own
    best = int(np.argmax(lifted.mean(axis=0)))
    fresh = {}
    if heldout:  # the best residual, chosen on these starts, and the prior alone on HELDOUT other starts
        env = make_env([(spec, model)] * heldout, cfg, seed=HELDOUT_SEED)
        fresh = dict(heldout=heldout, heldout_best=episode_scores(env, np.array(found[best]["best_theta"]), masks,
                                                                  HELDOUT_SEED, found[best].get("rot", 1.0))[0],
                     heldout_prior=episode_scores(env, np.zeros(len(found[best]["best_theta"])), masks,
                                                  HELDOUT_SEED)[0])
        env.close()
    print(json.dumps(dict(hand=hand, object=obj, starts=len(seeds), residuals=len(found),
                          own_start=float(np.sum(own)), off_diagonal_rate=round(float(lifted[other].mean()), 3),
                          starts_lifted_by_another=int(((lifted * other).max(axis=1) > 0).sum()),
                          best_residual_seed=found[best]["seed"], best_residual_rate=round(float(lifted[:, best].mean()), 3),
                          **fresh)), flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    heldout = int(args.pop(args.index("--heldout") + 1)) if "--heldout" in args else 0
    if "--heldout" in args:
        args.remove("--heldout")
    if len(args) < 2:
        sys.exit(__doc__)
    main(args[0], args[1:], heldout)
