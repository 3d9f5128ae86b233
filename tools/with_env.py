"""Copy a checkpoint with simulator (EnvConfig) fields changed, to evaluate a trained policy in an env it was not
trained in (a probe: does the policy's behaviour depend on this physics setting?). Only the manifest's ``env``
changes (validated by EnvConfig); the control contract, the weights and the ``train`` record are copied as they
are, so the copy is for ``dgz eval``, not for ``--resume``. Contract fields: tools/with_contract.py.

    .venv/bin/python tools/with_env.py docs/results/e19_checkpoint runs/e19_lead4 wrist_max_lead=0.004
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
        field, _, text = item.partition("=")
        if field == "contract" or field not in dump:
            raise SystemExit(f"{field}: no such env field (contract fields: tools/with_contract.py)")
        dump[field] = yaml.safe_load(text)
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
