"""How often lint's thumb-ROT warning (onboard.functional.rot_warnings) fires on generated hands: on the onboarded
(correct) specs, and with every thumb ROT sign flipped. docs/onboarding.md.
Run: .venv/bin/dgz hands generate --seed 0 --count 300 -o /tmp/gen300 && .venv/bin/python tools/probe_rot_warning.py /tmp/gen300"""

import collections
import sys
from pathlib import Path

from dgz_cli.onboard.agreement import compare
from dgz_cli.onboard.functional import rot_warnings
from dgz_cli.onboard.generate import load_labels
from dgz_cli.onboard.pipeline import onboard
from dgz_cli.spec.errors import DgzError

if __name__ == "__main__":
    counts: collections.Counter = collections.Counter()
    for urdf in sorted(Path(sys.argv[1]).glob("*.urdf")):
        try:
            result = onboard(urdf, "generated")
        except DgzError:
            counts["refused"] += 1
            continue
        spec = result.spec
        finger_of = {n.id: n.finger for n in spec.nodes}
        thumb_rot = [j.primitive.value == "ROT" and finger_of[j.node] == "thumb" for j in spec.joints]
        if not any(thumb_rot):
            counts["no thumb ROT"] += 1
            continue
        agree = not compare(spec, load_labels(urdf.with_name(urdf.name.replace(".urdf", ".labels.json"))))
        counts[f"{'agree' if agree else 'mismatch'}, warned" if rot_warnings(spec, result.poser)
               else f"{'agree' if agree else 'mismatch'}, no warning"] += 1
        rows = [j.model_copy(update=dict(sign=-j.sign)) if rot else j for j, rot in zip(spec.joints, thumb_rot)]
        flipped = spec.model_copy(update=dict(joints=rows))
        counts["flipped, warned" if rot_warnings(flipped, result.poser) else "flipped, missed"] += 1
    print(dict(counts))
