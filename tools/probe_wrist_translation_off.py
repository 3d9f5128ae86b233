"""Is a policy's wrist-translation residual what wins or loses a hand? A checkpoint evaluated in its own env twice
on the same start states: as trained, and with its wrist translation actions (the first three action dimensions)
set to zero at test time, so the palm follows the guidance and the lift alone while the rotation residual and the
fingers are unchanged. Per hand: the success rate both ways, per object, and the failure classes.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_wrist_translation_off.py CHECKPOINT HANDS OBJECTS TRIALS`"""
import json
import sys

import numpy as np

from dgz_cli.rl.checkpoint import LoadedPolicy
from dgz_cli.sim.evaluate import run_episodes, summarize
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec


class TranslationOff:
    """The checkpoint's policy with its wrist translation actions (B, 0:3) zeroed."""

    def __init__(self, policy: LoadedPolicy) -> None:
        self.policy = policy

    def reset(self, mask) -> None:
        self.policy.reset(mask)

    def act(self, obs) -> np.ndarray:
        a = np.array(self.policy.act(obs), dtype=np.float64, copy=True)
        a[:, :3] = 0.0
        return a


def main() -> None:
    if len(sys.argv) != 5:
        sys.exit(__doc__.splitlines()[-1])
    policy = LoadedPolicy(sys.argv[1])
    objects, trials = resolve_objects(sys.argv[3]), int(sys.argv[4])
    out = {}
    for hand in sys.argv[2].split(","):
        spec = load_spec(resolve_spec(hand))
        row = {}
        for mode, make in (("as trained", lambda env: policy), ("translation off", lambda env: TranslationOff(policy))):
            records = run_episodes([(spec, o) for o in objects], make, trials, policy.meta.env)
            (summary,) = summarize(records).values()
            per_object = {}
            for r in records:
                per_object.setdefault(r["object"], []).append(r["success"])
            row[mode] = dict(success=round(summary["success_rate"], 3), failures=summary["failures"],
                             objects={k: round(float(np.mean(v)), 2) for k, v in per_object.items()})
        out[hand] = row
        print(hand, json.dumps(row), flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
