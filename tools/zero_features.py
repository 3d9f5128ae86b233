"""Write copies of shipped hand specs with every physical-prior feature set to 0, to measure how much a trained
policy reads its physical priors at test time (the spec's name, joints, nodes, mask and M_h are unchanged, so the
simulated hand is the same; results stay keyed by the hand's name).

    .venv/bin/python tools/zero_features.py runs/nofeat inspire leap revo2
    dgz eval --policy docs/results/e19_checkpoint --hand runs/nofeat/inspire.yaml --zero-shot ...
"""

from __future__ import annotations

import sys
from pathlib import Path

import yaml

from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec


def main(out: str, hands: list[str]) -> None:
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    for hand in hands:
        data = yaml.safe_load(resolve_spec(hand).read_text())
        values = data["features"]["values"]
        for node in values:
            values[node] = [0.0] * len(values[node])
        path = folder / f"{hand}.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        load_spec(path)  # still a valid spec
        print(path)


if __name__ == "__main__":
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2:])
