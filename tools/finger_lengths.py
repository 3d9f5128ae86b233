"""Length of every finger of the shipped hands, from what the policy sees: the link vectors in each spec's physical
features (``link_x/y/z`` × ``features.normalization.length``), summed from the finger's second node to its tip.
The finger's first node hangs off the palm, so its link (palm → finger base) is left out. A finger whose first
node is a metacarpal inside the palm (Shadow's little finger) counts the metacarpal → knuckle link as well.

    .venv/bin/python tools/finger_lengths.py            # all shipped hands, mm
    .venv/bin/python tools/finger_lengths.py ability inspire
"""

from __future__ import annotations

import sys

import numpy as np

from dgz_cli.spec.catalog import resolve_spec, shipped_hands
from dgz_cli.spec.io import load_spec
from dgz_cli.spec.transform import LENGTH_FEATURES


def finger_lengths_mm(spec) -> dict[str, float]:
    cols = [spec.features.names.index(n) for n in LENGTH_FEATURES]
    scale = spec.features.normalization.length
    out: dict[str, float] = {}
    for node in spec.nodes:
        if node.finger == "wrist" or node.parent == "wrist":
            continue
        link = np.asarray(spec.features.values[node.id], dtype=float)[cols] * scale
        out[node.finger] = out.get(node.finger, 0.0) + float(np.linalg.norm(link)) * 1000.0
    return out


def main(hands: list[str]) -> None:
    for hand in hands or shipped_hands():
        lengths = finger_lengths_mm(load_spec(resolve_spec(hand)))
        print(f"{hand:12s} " + "  ".join(f"{f} {v:.0f}" for f, v in lengths.items()))


if __name__ == "__main__":
    main(sys.argv[1:])
