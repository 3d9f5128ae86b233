"""The finger lead cap (contract action.finger_max_lead) against no cap, for the guided scripted grasp and the
closing prior alone (zero residual, close_guide 0.08), same start states as tools/probe_prior_variants.py
(guidance 0.05, narrow roll, Markov layout, 10 objects × 2 slots × 1 episode per hand). With position control
the grip torque is finger_kp × (target − q), so a cap on the lead also caps the grip.
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_lead_cap.py [HANDS] [CAPS]"""

import json
import sys

from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import ActionLayout, ClosingPrior
from dgz_cli.spec.io import load_spec

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from probe_prior_variants import run  # noqa: E402

PRIOR = ClosingPrior(enabled=True, close_guide=0.08)

if __name__ == "__main__":
    hands = sys.argv[1].split(",") if len(sys.argv) > 1 else ["allegro", "shadow", "schunk_svh", "ability", "leap", "inspire"]
    caps = [None if c == "none" else float(c) for c in (sys.argv[2] if len(sys.argv) > 2 else "none,0.2").split(",")]
    out = {}
    for hand in hands:
        spec = load_spec(resolve_spec(hand))
        for cap in caps:
            for name, prior in (("scripted", None), ("prior guide.08", PRIOR)):
                key = f"{name} lead {cap}"
                out.setdefault(hand, {})[key] = run(spec, prior, ActionLayout(finger_max_lead=cap))
                print(hand, key, out[hand][key], flush=True)
    print(json.dumps(out))
