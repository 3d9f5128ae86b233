"""Where things live: shipped hand specs (``hand_specs/`` is the registry) and the asset root.

A spec names its URDF relative to the asset root (``--asset-root`` or ``DGZ_ASSET_ROOT``), or
as ``dgz://hands/<file>`` for the small hand models shipped inside the package.
"""

from __future__ import annotations

import os
from pathlib import Path

from dgz_cli.spec.errors import AssetError, SpecError

ASSET_ENV = "DGZ_ASSET_ROOT"
SPECS_ENV = "DGZ_HAND_SPECS"
PACKAGE_DATA = Path(__file__).resolve().parents[1] / "data"
BUILTIN_PREFIX = "dgz://"


def specs_dir() -> Path:
    """The shipped spec registry: $DGZ_HAND_SPECS, else ``hand_specs/`` beside the package."""
    env = os.environ.get(SPECS_ENV)
    return Path(env) if env else Path(__file__).resolve().parents[2] / "hand_specs"


def shipped_hands() -> list[str]:
    d = specs_dir()
    return sorted(p.stem for p in d.glob("*.yaml")) if d.is_dir() else []


def resolve_spec(name_or_path: str) -> Path:
    """A shipped hand name (``leap``) or a path to a spec file → the spec's path."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.exists():
        if not p.is_file():
            raise SpecError(f"{p}: no such spec file", "check the path")
        return p
    candidate = specs_dir() / f"{name_or_path}.yaml"
    if candidate.is_file():
        return candidate
    known = ", ".join(shipped_hands()) or "none found"
    raise SpecError(f"unknown hand '{name_or_path}'", f"use a spec path or one of: {known}")


def asset_root(option: str | Path | None = None, required: bool = False) -> Path | None:
    value = option if option not in (None, "") else os.environ.get(ASSET_ENV)
    if not value:
        if required:
            raise AssetError("no asset root set", f"pass --asset-root DIR or set {ASSET_ENV} (CI uses ../shared/assets)")
        return None
    root = Path(value).expanduser()
    if not root.is_dir():
        raise AssetError(f"asset root {root} is not a directory", f"fix --asset-root or {ASSET_ENV}")
    return root.resolve()


def urdf_reference(path: Path, root: Path | None) -> str:
    """How a spec records its source file: dgz://…, relative to the asset root, or absolute."""
    path = Path(path).resolve()
    if path.is_relative_to(PACKAGE_DATA):
        return BUILTIN_PREFIX + path.relative_to(PACKAGE_DATA).as_posix()
    if root is not None and path.is_relative_to(root):
        return path.relative_to(root).as_posix()
    return str(path)


def resolve_urdf(reference: str, root_option: str | Path | None = None) -> Path:
    """A spec's ``provenance.urdf`` → the file on this machine."""
    if reference.startswith(BUILTIN_PREFIX):
        return PACKAGE_DATA / reference[len(BUILTIN_PREFIX):]
    p = Path(reference)
    if p.is_absolute():
        return p
    root = asset_root(root_option, required=True)
    full = root / p
    if not full.is_file():
        raise AssetError(f"{reference} not found under the asset root {root}",
                         f"point --asset-root / {ASSET_ENV} at the folder that holds hands/ and objects/")
    return full
