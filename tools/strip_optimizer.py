"""Copy a checkpoint folder without its optimizer state, for shipping in policies/ (a --resume from the copy
starts a fresh Adam). The model tensors are checked to be identical after the round trip.

    .venv/bin/python tools/strip_optimizer.py runs/distill-nocap policies/dgz-cpu-student
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import torch

from dgz_cli.rl.checkpoint import load, save


def main(src: str, dst: str) -> None:
    tensors, meta = load(Path(src))
    kept = {k: v for k, v in tensors.items() if not k.startswith("optim.")}
    out = Path(dst)
    out.mkdir(parents=True, exist_ok=True)
    save(out, kept, meta)
    again, _ = load(out)
    assert again.keys() == kept.keys() and all(torch.equal(again[k], kept[k]) for k in kept)
    for name in ("history.csv", "history.jsonl", "curve.png"):
        if (Path(src) / name).is_file():
            shutil.copy2(Path(src) / name, out / name)
    print(f"{dst}: {len(kept)} model tensors kept, {len(tensors) - len(kept)} optimizer tensors dropped")


if __name__ == "__main__":
    main(*sys.argv[1:3])
