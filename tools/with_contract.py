"""Copy a checkpoint with control-contract fields (or, prefixed ``env.``, simulator EnvConfig fields) changed, to
evaluate a trained policy under a contract or in an env it was not trained with (a probe before a fine-tune: does
the lever help the policy as it is?). Only the manifest's ``env`` (with its ``contract``) changes, validated by
EnvConfig and the contract's own model; the weights and the ``train`` record are copied as they are, so the copy
is for ``dgz eval``, not for ``--resume``.

    .venv/bin/python tools/with_contract.py docs/results/e19_checkpoint runs/e19_stop05 guidance.stop_gap=0.05
    .venv/bin/python tools/with_contract.py docs/results/e19_checkpoint runs/e19_lead4 env.wrist_max_lead=0.004
"""

from __future__ import annotations

import sys
from pathlib import Path

import yaml

from dgz_cli.rl.checkpoint import load, save


def main(src: str, dst: str, assignments: list[str]) -> None:
    tensors, meta = load(Path(src))
    dump = meta.env.model_dump()
    for item in assignments:
        path, _, text = item.partition("=")
        *parents, field = path.split(".")
        scope = "env" if parents[:1] == ["env"] else "contract"
        node = dump if scope == "env" else dump["contract"]
        for p in parents[1:] if scope == "env" else parents:
            node = node[p]
        if field not in node or (scope == "env" and field == "contract"):
            raise SystemExit(f"{path}: no such {scope} field")
        node[field] = yaml.safe_load(text)
    env = type(meta.env).model_validate(dump)
    meta = meta.model_copy(update=dict(env=env))
    out = Path(dst)
    out.mkdir(parents=True, exist_ok=True)
    save(out, tensors, meta)
    load(out)  # the copy reads back (hash, manifest)
    print(f"{dst}: {src} with {', '.join(assignments)}")


if __name__ == "__main__":
    if len(sys.argv) < 4:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
