"""Where things live: shipped hands (``hand_specs/`` is the registry) and the asset root.

One hand, one folder: ``hand_specs/<hand>/`` holds ``spec.yaml`` (the HandSpec), ``overrides.yaml``
(human overrides, if any), ``hardware.yaml`` (the hardware control table, if the hand has a driver)
and a provenance ``README.md``. A spec names its URDF relative to the asset root (``--asset-root``
or ``DGZ_ASSET_ROOT``, else the folder `dgz assets fetch` fills by default), or as ``dgz://hands/<file>`` for
the small hand models shipped inside the package.

``hand_specs/`` and ``policies/`` are top-level folders of the checkout; a wheel carries them as package data
under ``dgz_cli/shipped/`` (see setup.py). :func:`specs_dir` and :func:`policies_dir` find either.
"""

from __future__ import annotations

import os
from pathlib import Path

from dgz_cli.spec.errors import AssetError, SpecError

ASSET_ENV = "DGZ_ASSET_ROOT"
SPECS_ENV = "DGZ_HAND_SPECS"
PACKAGE_DATA = Path(__file__).resolve().parents[1] / "data"
BUILTIN_PREFIX = "dgz://"
SPEC_FILE = "spec.yaml"
HARDWARE_FILE = "hardware.yaml"
ASSET_MARKER = ".dgz-assets.json"  # written last by `dgz assets fetch` into the asset root it filled
SHIPPED_IN_PACKAGE = Path(__file__).resolve().parents[1] / "shipped"  # wheel installs (setup.py copies them)
CHECKOUT = Path(__file__).resolve().parents[2]


def _shipped(folder: str) -> Path:
    """``hand_specs`` or ``policies``: inside the installed package (a wheel), else beside it (a checkout)."""
    packaged = SHIPPED_IN_PACKAGE / folder
    return packaged if packaged.is_dir() else CHECKOUT / folder


def specs_dir() -> Path:
    """The shipped hand registry: $DGZ_HAND_SPECS, else ``hand_specs/`` (checkout or package data)."""
    env = os.environ.get(SPECS_ENV)
    return Path(env) if env else _shipped("hand_specs")


def policies_dir() -> Path:
    """The shipped policies: ``policies/`` (checkout or package data)."""
    return _shipped("policies")


def policy_ref(ref: str) -> str:
    """A ``--policy`` value with a bare shipped name (``dgz-cpu-warmstart``) turned into its folder's path, so it
    resolves in a wheel install as in a checkout; anything else is returned unchanged."""
    if ref and "/" not in ref and "\\" not in ref and ref not in (".", "..") and not Path(ref).is_dir():
        candidate = policies_dir() / ref
        if candidate.is_dir():
            return str(candidate)
    return ref


def default_asset_dir() -> Path:
    """Where `dgz assets fetch` puts the asset root by default: the user's cache folder (platformdirs)."""
    import platformdirs

    return Path(platformdirs.user_cache_dir("dgz")) / "assets"


def hand_dir(name: str) -> Path:
    """The folder of shipped hand ``name`` (it may not exist)."""
    return specs_dir() / name


def shipped_hands() -> list[str]:
    """Names of the shipped hands: the folders of the registry that hold a ``spec.yaml``."""
    d = specs_dir()
    return sorted(p.parent.name for p in d.glob(f"*/{SPEC_FILE}")) if d.is_dir() else []


def hand_name(spec_path: Path) -> str:
    """The name a spec file is known by: its folder's for ``<hand>/spec.yaml``, else the file stem."""
    p = Path(spec_path)
    return p.parent.resolve().name if p.name == SPEC_FILE else p.stem


def resolve_spec(name_or_path: str) -> Path:
    """A shipped hand name (``leap``), a hand folder or a path to a spec file → the spec's path."""
    p = Path(name_or_path)
    if (p / SPEC_FILE).is_file():
        return p / SPEC_FILE
    if p.suffix in (".yaml", ".yml") or (p.exists() and not p.is_dir()):
        if not p.is_file():
            raise SpecError(f"{p}: no such spec file", "check the path")
        return p
    candidate = hand_dir(name_or_path) / SPEC_FILE
    if candidate.is_file():
        return candidate
    if p.is_dir():
        raise SpecError(f"{p}: the folder holds no {SPEC_FILE}", "name a spec file, a hand folder or a shipped hand")
    known = ", ".join(shipped_hands()) or "none found"
    raise SpecError(f"unknown hand '{name_or_path}'", f"use a spec path or one of: {known}")


def asset_root(option: str | Path | None = None, required: bool = False) -> Path | None:
    """``--asset-root``, else $DGZ_ASSET_ROOT, else the default folder of `dgz assets fetch` once it holds a fetch."""
    value = option if option not in (None, "") else os.environ.get(ASSET_ENV)
    if not value:
        fetched = default_asset_dir()
        if (fetched / ASSET_MARKER).is_file():
            return fetched.resolve()
        if required:
            raise AssetError("no asset root set", f"run `dgz assets fetch`, pass --asset-root DIR or set {ASSET_ENV} "
                                                  "(CI uses ../shared/assets)")
        return None
    root = Path(value).expanduser()
    if not root.is_dir():
        raise AssetError(f"asset root {root} is not a directory", f"fix --asset-root or {ASSET_ENV}")
    return root.resolve()


def urdf_reference(path: Path, root: Path | None) -> str:
    """How a spec records its source file: dgz://…, relative to the asset root, or absolute."""
    given, path = Path(path).absolute(), Path(path).resolve()
    if path.is_relative_to(PACKAGE_DATA):
        return BUILTIN_PREFIX + path.relative_to(PACKAGE_DATA).as_posix()
    if root is not None:  # a symlinked asset root (or hand folder) still gives a relative reference
        for p, r in ((path, Path(root).resolve()), (given, Path(root).absolute())):
            if p.is_relative_to(r):
                return p.relative_to(r).as_posix()
    return str(path)


def resolve_urdf(reference: str, root_option: str | Path | None = None) -> Path:
    """A spec's ``provenance.urdf`` → the file on this machine.

    ``dgz://`` names stay inside the package data and relative names inside the asset root (no ``..``
    escape); whatever is named must be a regular file (not a device, FIFO or folder).
    """
    if "\x00" in reference:
        raise AssetError(f"provenance.urdf {reference!r} contains a NUL character", "fix provenance.urdf in the spec")
    if reference.startswith(BUILTIN_PREFIX):
        full = _inside_root(PACKAGE_DATA, reference[len(BUILTIN_PREFIX):], reference, "the package's data folder")
        return _regular(full, reference)
    p = Path(reference)
    if p.is_absolute():
        return _regular(p, reference)
    root = asset_root(root_option, required=True)
    full = _inside_root(root, reference, reference, f"the asset root {root}")
    if not full.exists():
        raise AssetError(f"{reference} not found under the asset root {root}",
                         f"point --asset-root / {ASSET_ENV} at the folder that holds hands/ and objects/")
    return _regular(full, reference)


def _inside_root(root: Path, relative: str, reference: str, where: str) -> Path:
    """``root / relative``, refusing absolute parts and ``..`` that would leave ``root``."""
    rel = Path(relative)
    full = Path(os.path.normpath(Path(root) / rel))
    base = Path(os.path.normpath(root))
    if rel.is_absolute() or not (full == base or base in full.parents):
        raise AssetError(f"provenance.urdf '{reference}' leaves {where}",
                         "a relative name must stay inside its root (no '..'); fix provenance.urdf in the spec")
    return full


def _regular(path: Path, reference: str) -> Path:
    import stat

    try:
        mode = os.stat(path).st_mode
    except OSError:
        raise AssetError(f"provenance.urdf '{reference}': no such file ({path})",
                         f"check the path, or point --asset-root / {ASSET_ENV} at the asset folder") from None
    if not stat.S_ISREG(mode):
        raise AssetError(f"provenance.urdf '{reference}' is not a regular file ({path})",
                         "name a URDF or xacro file, not a device, FIFO or folder")
    return path
