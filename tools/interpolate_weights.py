"""Write a checkpoint whose weights are a linear interpolation of two checkpoints of one network, to evaluate a
fine-tune's trade between its training distribution and the hands it never saw (weight-space ensembling, as in
WiSE-FT: Wortsman et al., "Robust fine-tuning of zero-shot models", CVPR 2022).

    θ(α) = (1 − α)·θ_A + α·θ_B        (every network tensor, log-stds included; optimizer state is dropped)

The copy takes B's manifest (its control contract, run config and training hands), so it runs under B's contract,
and it is for ``dgz eval``, not for ``--resume``. A and B must share the network config and every tensor's name and
shape (B fine-tuned from A, e.g. E19 from E16).

    .venv/bin/python tools/interpolate_weights.py docs/results/e16y45_checkpoint docs/results/e19_checkpoint 0.5 runs/wise50
"""

from __future__ import annotations

import sys
from pathlib import Path

from dgz_cli.rl.checkpoint import load, save


def main(src_a: str, src_b: str, alpha: float, dst: str) -> None:
    if not 0.0 <= alpha <= 1.0:
        raise SystemExit(f"alpha {alpha}: give a number from 0 (all A) to 1 (all B)")
    tensors_a, meta_a = load(Path(src_a))
    tensors_b, meta_b = load(Path(src_b))
    tensors_a, tensors_b = ({k: v for k, v in t.items() if k.startswith("model.")} for t in (tensors_a, tensors_b))
    if meta_a.model != meta_b.model or meta_a.student is not None or meta_b.student is not None:
        raise SystemExit(f"{src_a} and {src_b}: interpolate two teachers of one network config")
    if tensors_a.keys() != tensors_b.keys() or any(tensors_a[k].shape != tensors_b[k].shape for k in tensors_a):
        raise SystemExit(f"{src_a} and {src_b}: the tensors' names or shapes differ")
    mixed = {k: ((1.0 - alpha) * tensors_a[k].double() + alpha * tensors_b[k].double()).to(tensors_b[k].dtype)
             for k in tensors_b}
    out = Path(dst)
    out.mkdir(parents=True, exist_ok=True)
    save(out, mixed, meta_b.model_copy(update=dict(pair_success=None)))
    load(out)  # the copy reads back (hash, manifest)
    print(f"{dst}: (1 - {alpha})·{src_a} + {alpha}·{src_b}, under {src_b}'s manifest")


if __name__ == "__main__":
    if len(sys.argv) != 5:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4])
