"""Is a policy's wrist-translation residual what wins or loses a hand? A checkpoint evaluated in its own env twice
on the same start states: as trained, and with its wrist translation actions (the first three action dimensions)
scaled by 0 at test time through the contract's own factor (`wrist_translation_residual` 0, as sim and deploy apply
it), so the palm follows the guidance and the lift alone while the rotation residual and the fingers are unchanged.
Per hand: the success rate both ways, per object, and the failure classes.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_wrist_translation_off.py CHECKPOINT HANDS OBJECTS TRIALS`"""
import json
import sys

from dgz_cli.rl.checkpoint import LoadedPolicy
from dgz_cli.sim.evaluate import run_episodes, summarize
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec


def main() -> None:
    if len(sys.argv) != 5:
        sys.exit(__doc__.splitlines()[-1])
    policy = LoadedPolicy(sys.argv[1])
    objects, trials = resolve_objects(sys.argv[3]), int(sys.argv[4])
    own = policy.meta.env
    action = own.contract.action.model_copy(update=dict(wrist_translation_residual=0.0))
    translation_off = own.model_copy(update=dict(contract=own.contract.model_copy(update=dict(action=action))))
    out = {}
    for hand in sys.argv[2].split(","):
        spec = load_spec(resolve_spec(hand))
        row = {}
        for mode, cfg in (("as trained", own), ("translation off", translation_off)):
            records = run_episodes([(spec, o) for o in objects], lambda env: policy, trials, cfg)
            (summary,) = summarize(records).values()
            row[mode] = dict(success=round(summary["success_rate"], 3), failures=summary["failures"],
                             objects={k: round(o["success_rate"], 2) for k, o in summary["objects"].items()})
        out[hand] = row
        print(hand, json.dumps(row), flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
