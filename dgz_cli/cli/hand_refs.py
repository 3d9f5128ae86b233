"""The hands a command names (`--hands` of train and distill, `--hand` of eval) as spec files."""

from __future__ import annotations

from pathlib import Path


def hand_specs(hands, asset_root: str | None, option: str = "--hands") -> dict[str, Path]:
    """``--hands`` entries → spec paths by hand name: shipped names and spec paths as they are, and
    ``generated:DIR`` as every hand in DIR (onboarded there unless a current spec is already beside it).
    ``option`` is the flag the entries came from, for messages (`dgz eval` names its ``--hand``)."""
    from dgz_cli.onboard.folder import PREFIX, onboard_folder
    from dgz_cli.spec.catalog import asset_root as resolve_root
    from dgz_cli.spec.catalog import hand_name, resolve_spec
    from dgz_cli.spec.errors import DgzError

    out: dict[str, Path] = {}
    for h in hands:
        if h.startswith(PREFIX):
            folder = Path(h[len(PREFIX):]).expanduser()
            paths = onboard_folder(folder, resolve_root(asset_root), f"{option} {h}")
        else:
            paths = [resolve_spec(h)]
        for p in paths:
            name = hand_name(p) if h.startswith(PREFIX) else h
            if name in out:
                raise DgzError(f"{option}: hand '{name}' is named twice ({out[name]} and {p})",
                               "name each hand once; rename one of the URDFs")
            out[name] = p
    return out
