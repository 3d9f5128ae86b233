"""Which palm axis of a policy's wrist-translation residual wins or loses a hand? A checkpoint evaluated in its own
env on the same start states with its wrist translation actions (action dims 0, 1, 2 = Δp along the palm's f, l, n
axes) zeroed on a chosen set of axes at test time, which is what a per-axis `wrist_translation_residual` of 0 would
do; the rotation residual and the fingers are unchanged. Modes: as trained, l off, n off, f and n off (l kept), all off
(the whole translation residual). Per hand and mode: the success rate, per object, and the failure classes.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_wrist_axes.py CHECKPOINT HANDS OBJECTS TRIALS`"""
import json
import sys

import numpy as np
from probe_common import checkpoint_summary

from dgz_cli.rl.checkpoint import LoadedPolicy

MODES = {"as trained": (), "l off": (1,), "n off": (2,), "f, n off": (0, 2), "all off": (0, 1, 2)}


class AxesOff:
    """The policy with its wrist translation actions on ``axes`` set to 0 (what the env then scales by its factor)."""

    def __init__(self, policy: LoadedPolicy, axes: tuple[int, ...]) -> None:
        self.policy, self.axes = policy, list(axes)

    def reset(self, mask) -> None:
        self.policy.reset(mask)

    def act(self, obs) -> np.ndarray:
        action = np.array(self.policy.act(obs), copy=True)
        action[:, self.axes] = 0.0
        return action


def main() -> None:
    if len(sys.argv) != 5:
        sys.exit(__doc__.splitlines()[-1])
    policy = LoadedPolicy(sys.argv[1])
    objects, trials = sys.argv[3], int(sys.argv[4])
    out = {}
    for hand in sys.argv[2].split(","):
        row = {}
        for mode, axes in MODES.items():
            summary = checkpoint_summary(policy, hand, objects, trials, lambda env: AxesOff(policy, axes))
            row[mode] = dict(success=round(summary["success_rate"], 3), failures=summary["failures"],
                             objects={k: round(o["success_rate"], 2) for k, o in summary["objects"].items()})
        out[hand] = row
        print(hand, json.dumps({m: (r["success"], list(r["failures"].values())[:4]) for m, r in row.items()}), flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
