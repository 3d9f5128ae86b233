"""The asset registry: upstream sources at fixed commits and, per unit, the files taken from them.

A *unit* is what is installed (and replaced) as a whole with one rename: ``hands/<hand>`` or
``objects/ycb45``. Every file names its source archive, the member inside it (below the archive's top
folder), and how it is produced: copied as is, copied after exact ``[old, new]`` text replacements, or
converted (``glb2obj``). ``sha256`` is the expected sha256 of the installed file (``None`` only for converted
visuals, whose bytes depend on the converter); ``source_sha256`` that of the member when it is not copied
as is. Both were measured from the upstream repositories by ``tools/asset_registry.py``.
"""

from __future__ import annotations

import json
import re
from functools import lru_cache
from pathlib import Path, PurePosixPath
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from dgz_cli.spec.errors import AssetError

REGISTRY_FILE = Path(__file__).resolve().parent / "registry.json"
SHA256 = r"^[0-9a-f]{64}$"
MAX_REGISTRY_BYTES = 8 * 1024 * 1024


def _relative(value: str) -> str:
    p = PurePosixPath(value)
    if not value or p.is_absolute() or ".." in p.parts or "\\" in value or "\x00" in value or value != p.as_posix():
        raise ValueError(f"{value!r} is not a plain relative path")
    return value


class Source(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")
    repo: str = Field(pattern=r"^[A-Za-z0-9_.-]+/[A-Za-z0-9_.-]+$", description="owner/name of the upstream repository")
    commit: str = Field(pattern=r"^[0-9a-f]{40}$")
    licence: str = Field(max_length=200)
    url: str = Field(pattern=r"^(https?|file)://", max_length=500, description="the archive at that commit")
    archive: str = Field(pattern=r"^[A-Za-z0-9_.-]+\.tar\.gz$", description="file name of the downloaded archive")
    prefix: str = Field(max_length=200, description="top folder inside the archive, with a trailing /")
    sha256: str | None = Field(default=None, pattern=SHA256,
                               description="archive sha256 when it could be measured; else every file is checked")
    max_bytes: int = Field(default=2 << 30, gt=0, le=16 << 30, description="refuse a larger download")

    @field_validator("prefix")
    @classmethod
    def _prefix(cls, v: str) -> str:
        if not v.endswith("/"):
            raise ValueError("prefix must end with /")
        _relative(v.rstrip("/"))
        return v


class FileEntry(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")
    source: str
    member: str
    sha256: str | None = Field(default=None, pattern=SHA256)
    source_sha256: str | None = Field(default=None, pattern=SHA256)
    replace: tuple[tuple[str, str], ...] = ()
    convert: Literal["glb2obj"] | None = None
    note: str | None = Field(default=None, max_length=200)

    @field_validator("member")
    @classmethod
    def _member(cls, v: str) -> str:
        return _relative(v)


class Unit(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")
    files: dict[str, FileEntry]

    @field_validator("files")
    @classmethod
    def _paths(cls, v: dict[str, FileEntry]) -> dict[str, FileEntry]:
        for k in v:
            _relative(k)
        return v


class Registry(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")
    format: Literal[1]
    note: str = ""
    sources: dict[str, Source]
    units: dict[str, Unit]

    @field_validator("units")
    @classmethod
    def _units(cls, v: dict[str, Unit]) -> dict[str, Unit]:
        for k in v:
            if not re.fullmatch(r"(hands/[a-z0-9_]+|objects/[a-z0-9_]+)", k):
                raise ValueError(f"unit {k!r} is not hands/<name> or objects/<set>")
        return v

    def hands(self) -> list[str]:
        return sorted(k.split("/", 1)[1] for k in self.units if k.startswith("hands/"))

    def object_sets(self) -> list[str]:
        return sorted(k.split("/", 1)[1] for k in self.units if k.startswith("objects/"))

    def select(self, hands: list[str] | None, objects: list[str] | None) -> list[str]:
        """Unit names for ``--hands`` (None or ``all``: every hand) and ``--objects`` (None: ycb45; ``none``)."""
        chosen: list[str] = []
        for kind, names, known, default in (("hands", hands, self.hands(), self.hands()),
                                            ("objects", objects, self.object_sets(), self.object_sets())):
            names = default if names is None or names == ["all"] else [n for n in names if n != "none"]
            for n in names:
                if n not in known:
                    raise AssetError(f"--{kind} {n!r}: not in the asset registry",
                                     f"choose from: {', '.join(known)} (or all, none)")
                chosen.append(f"{kind}/{n}")
        if not chosen:
            raise AssetError("nothing selected", "name --hands and/or --objects (e.g. --hands leap --objects ycb45)")
        return chosen

    def check(self, where: str) -> Registry:
        for unit, u in self.units.items():
            for path, f in u.files.items():
                if f.source not in self.sources:
                    raise AssetError(f"{where}: {unit}/{path} names unknown source {f.source!r}", "fix the registry")
                if f.sha256 is None and f.convert is None:
                    raise AssetError(f"{where}: {unit}/{path} has no sha256", "every copied file must be pinned")
        return self


def load_registry(path: Path | None = None) -> Registry:
    """The shipped registry (or ``path``), schema-checked; a bad file is one line naming it and the field."""
    path = Path(path) if path is not None else REGISTRY_FILE
    try:
        if path.stat().st_size > MAX_REGISTRY_BYTES:
            raise AssetError(f"{path}: larger than {MAX_REGISTRY_BYTES >> 20} MB", "is this an asset registry?")
        raw = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise AssetError(f"cannot read the asset registry {path}: {exc.strerror}", "reinstall dgz") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise AssetError(f"{path}: malformed JSON ({exc})", "restore the registry file") from None
    try:
        return Registry.model_validate(raw).check(str(path))
    except ValidationError as exc:
        e = exc.errors()[0]
        loc = ".".join(str(x) for x in e["loc"])
        raise AssetError(f"{path}: {loc}: {e['msg']}", "restore the registry file") from None


@lru_cache(maxsize=1)
def shipped_registry() -> Registry:
    return load_registry()
