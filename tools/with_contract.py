"""Copy a checkpoint with control-contract fields changed, to evaluate a trained policy under a contract it was
not trained with (a probe before a fine-tune: does the lever help the policy as it is?). Only the manifest's
``env.contract`` changes (validated by the contract's own model); the weights and the ``train`` record are
copied as they are, so the copy is for ``dgz eval``, not for ``--resume``.

    .venv/bin/python tools/with_contract.py docs/results/e19_checkpoint runs/e19_stop05 guidance.stop_gap=0.05
"""

from __future__ import annotations

import sys
from pathlib import Path

import yaml

from dgz_cli.rl.checkpoint import load, save
from dgz_cli.spec.contract import ControlContract


def main(src: str, dst: str, assignments: list[str]) -> None:
    tensors, meta = load(Path(src))
    dump = meta.env.contract.model_dump()
    for item in assignments:
        path, _, text = item.partition("=")
        *parents, field = path.split(".")
        node = dump
        for p in parents:
            node = node[p]
        if field not in node:
            raise SystemExit(f"{path}: no such contract field")
        node[field] = yaml.safe_load(text)
    contract = ControlContract.model_validate(dump)
    meta = meta.model_copy(update=dict(env=meta.env.model_copy(update=dict(contract=contract))))
    out = Path(dst)
    out.mkdir(parents=True, exist_ok=True)
    save(out, tensors, meta)
    load(out)  # the copy reads back (hash, manifest)
    print(f"{dst}: {src} with {', '.join(assignments)}")


if __name__ == "__main__":
    if len(sys.argv) < 4:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
