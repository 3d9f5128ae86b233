"""Where each hand's thumb opposes its fingers, in the palm frame (f, l, n), at a checkpoint's start pose (the
contract's thumb opening): the guidance's grasp point (the mean of every node anchor), the thumb tip, the mean of
the other fingertips, and the midpoint of those two, in mm. Compares, along the palm's lateral axis l, where the
hands grasp with the wrist offset a policy learned (docs/training.md, "Which palm axis").

    DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/opposition_points.py docs/results/e19_checkpoint
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from dgz_cli.rl.checkpoint import read_meta
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec
from dgz_cli.spec.kinematics import HandKinematics
from probe_common import open_hand_tips

HANDS = "allegro shadow schunk_svh ability leap inspire revo2 barrett".split()


def main(checkpoint: str) -> None:
    start = read_meta(Path(checkpoint)).env.contract.start
    print(f"# {checkpoint}'s start pose (thumb_open {start.thumb_open} on {', '.join(start.thumb_primitives)}); "
          "palm frame (f, l, n), mm")
    print("# hand | grasp point (all nodes) | thumb tip | other fingertips, mean | thumb-to-fingers midpoint")
    for hand in HANDS:
        spec = load_spec(resolve_spec(hand))
        q = start.pose(spec)
        grasp_point = HandKinematics.for_spec(spec).anchors_palm(q).mean(0)
        thumb, others = open_hand_tips(spec, q)
        cells = [c * 1000.0 for c in (grasp_point, thumb, others, (thumb + others) / 2)]
        print(hand, *(np.round(c).astype(int).tolist() for c in cells), sep=" | ")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    main(sys.argv[1])
