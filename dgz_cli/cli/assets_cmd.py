"""`dgz assets fetch`: lay out an asset root from the pinned upstream archives (logic in dgz_cli.assets)."""

from __future__ import annotations

import os
from pathlib import Path

from rich.console import Console
from rich.markup import escape


def _names(values: list[str] | None) -> list[str] | None:
    if values is None:
        return None
    return [n.strip() for v in values for n in v.split(",") if n.strip()]


def fetch(hands: list[str] | None, objects: list[str] | None, dest: Path | None, mirror: str | None, force: bool,
          registry_file: Path | None, console: Console, progress: bool = True) -> int:
    from dgz_cli.assets.fetch import fetch as run_fetch
    from dgz_cli.assets.registry import load_registry, shipped_registry
    from dgz_cli.spec.catalog import ASSET_ENV, default_asset_dir

    registry = load_registry(registry_file) if registry_file is not None else shipped_registry()
    units = registry.select(_names(hands), _names(objects))
    target = dest if dest is not None else default_asset_dir()
    console.print(f"fetching {', '.join(units)} into {escape(str(target))}", highlight=False, soft_wrap=True)
    report = run_fetch(units, target, mirror=mirror, registry=registry, force=force, progress=progress,
                       log=lambda s: console.print(f"  {escape(s)}", highlight=False, soft_wrap=True))
    for name, digest in report.archives.items():
        pinned = any(s.archive == name and s.sha256 for s in registry.sources.values())
        console.print(f"  [dim]{escape(name)} sha256 {digest}" + ("" if pinned else " (archive not pinned: every "
                      "file taken from it was checked against the registry)") + "[/]", highlight=False, soft_wrap=True)
    if report.already:
        console.print(f"  already there and verified: {', '.join(report.already)} [dim](--force fetches again)[/]",
                      highlight=False, soft_wrap=True)
    root = report.dest.resolve()
    console.print(f"[green]asset root ready:[/] {escape(str(root))}", highlight=False, soft_wrap=True)
    env = os.environ.get(ASSET_ENV)
    if env and Path(env).expanduser().resolve() != root:
        console.print(f"[yellow]note:[/] {ASSET_ENV}={escape(env)} is set and takes priority; unset it or point it "
                      f"at {escape(str(root))}", highlight=False, soft_wrap=True)
    elif dest is not None and root != default_asset_dir().resolve():
        console.print(f"  use it with --asset-root {escape(str(root))} or export {ASSET_ENV}={escape(str(root))}",
                      highlight=False, soft_wrap=True)
    else:
        console.print(f"  [dim]dgz finds it without {ASSET_ENV}[/]", highlight=False, soft_wrap=True)
    return 0
