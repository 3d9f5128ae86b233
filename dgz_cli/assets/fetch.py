"""Download, verify and install asset units (see :mod:`dgz_cli.assets`).

The order of work makes a half-installed unit impossible:

1. each archive is downloaded by pooch into ``DEST/.downloads/`` through :class:`ResumingDownloader`, which keeps
   the bytes received so far in ``<archive>.part`` and asks for the rest (HTTP Range) on the next run; pooch
   checks the archive's sha256 when the registry pins one and only then renames the file into place;
2. the members the selected units need are read from the archive (``tarfile``'s ``data`` filter refuses links,
   devices, absolute names and ``..``; only regular files of bounded size are read) into a staging folder
   ``DEST/.staging-*`` next to the destination, edited or converted as the registry says, and every file is
   checked against its sha256;
3. each verified unit (``hands/leap``) is moved into place with one ``rename``; a unit that was already there is
   renamed aside first and removed after. ``DEST/.dgz-assets.json`` is written last (atomically) and is what
   lets dgz use ``DEST`` without ``DGZ_ASSET_ROOT``.

Any failure removes the staging folder; the units already in ``DEST`` stay as they were.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import sys
import tarfile
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from dgz_cli.assets.registry import FileEntry, Registry, Source, shipped_registry
from dgz_cli.spec.catalog import ASSET_MARKER, default_asset_dir
from dgz_cli.spec.errors import AssetError

MIRROR_ENV = "DGZ_ASSET_MIRROR"
DOWNLOADS = ".downloads"
MAX_MEMBER_BYTES = 256 * 1024 * 1024   # one file taken from an archive
MAX_EDIT_BYTES = 64 * 1024 * 1024      # a file that is edited in memory (URDF, model.xml) or converted
CHUNK = 1 << 16


@dataclass
class FetchReport:
    dest: Path
    installed: list[str] = field(default_factory=list)
    already: list[str] = field(default_factory=list)
    archives: dict[str, str] = field(default_factory=dict)  # archive file → its sha256 (measured)
    files: int = 0


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _disk_error(exc: OSError, path: Path, what: str) -> AssetError:
    if exc.errno == errno.ENOSPC:
        return AssetError(f"no space left on the device while {what} ({path})",
                          "free some space or pass --dest DIR on another disk, then run the same command again")
    if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return AssetError(f"cannot write {path} while {what}: {exc.strerror}", "pass --dest DIR to a writable folder")
    return AssetError(f"{what} failed at {path}: {exc.strerror or exc}", "check the destination folder, then retry")


class ResumingDownloader:
    """A pooch downloader (``downloader(url, output_file, pooch)``) that resumes: bytes received are kept in
    ``part`` and the next call asks only for the rest with an HTTP Range request; a tqdm bar shows progress
    on stderr. The finished file is moved onto pooch's temporary ``output_file`` (same folder)."""

    def __init__(self, part: Path, max_bytes: int, progress: bool = True, timeout: float = 30.0) -> None:
        self.part, self.max_bytes, self.progress, self.timeout = Path(part), max_bytes, progress, timeout

    def __call__(self, url: str, output_file, pooch, check_only: bool = False):  # noqa: ARG002 (pooch's signature)
        import requests
        from tqdm import tqdm

        have = self.part.stat().st_size if self.part.is_file() else 0
        headers = {"Range": f"bytes={have}-"} if have else {}
        with requests.get(url, stream=True, timeout=self.timeout, headers=headers) as r:
            if have and r.status_code == 416:  # nothing left to send: the part is the whole file
                os.replace(self.part, output_file)
                return None
            r.raise_for_status()
            if r.status_code != 206:
                have = 0  # the server ignored the range: start over
            length = r.headers.get("Content-Length")
            total = have + int(length) if length and length.isdigit() else None
            if total is not None and total > self.max_bytes:
                raise AssetError(f"{url}: {total} bytes, more than the registry allows ({self.max_bytes})",
                                 "the upstream archive changed; update dgz or use a --mirror that serves the pinned one")
            bar = tqdm(total=total, initial=have, unit="B", unit_scale=True, unit_divisor=1024, leave=False,
                       desc=self.part.name.removesuffix(".part"), disable=not self.progress, file=sys.stderr)
            try:
                with open(self.part, "ab" if have else "wb") as f:
                    for chunk in r.iter_content(CHUNK):
                        if not chunk:
                            continue
                        have += len(chunk)
                        if have > self.max_bytes:
                            raise AssetError(f"{url}: more than {self.max_bytes} bytes",
                                             "the upstream archive changed; update dgz or use a --mirror")
                        f.write(chunk)
                        bar.update(len(chunk))
            except OSError as exc:
                if isinstance(exc, requests.RequestException):
                    raise
                raise _disk_error(exc, self.part, "downloading") from None
            finally:
                bar.close()
        if total is not None and have < total:
            raise requests.exceptions.ChunkedEncodingError(f"connection closed after {have} of {total} bytes")
        os.replace(self.part, output_file)
        return None


def archive_url(source: Source, mirror: str | None) -> str:
    """The registry's URL, or ``MIRROR/<archive file name>`` when a mirror is given (--mirror, $DGZ_ASSET_MIRROR)."""
    mirror = mirror or os.environ.get(MIRROR_ENV) or None
    return mirror.rstrip("/") + "/" + source.archive if mirror else source.url


def download(source: Source, url: str, downloads: Path, progress: bool = True) -> Path:
    """The archive in ``downloads`` (downloaded, or resumed, unless it is already there), as pooch checks it."""
    import logging

    import pooch
    import requests

    pooch.get_logger().setLevel(logging.WARNING)  # dgz prints its own lines
    part = downloads / (source.archive + ".part")
    known = f"sha256:{source.sha256}" if source.sha256 else None
    try:
        return Path(pooch.retrieve(url, known_hash=known, fname=source.archive, path=downloads,
                                   downloader=ResumingDownloader(part, source.max_bytes, progress)))
    except (requests.exceptions.ChunkedEncodingError, requests.exceptions.ConnectionError) as exc:
        text = str(exc)
        kept = f"; {part.stat().st_size} bytes kept for resuming" if part.is_file() else ""
        if isinstance(exc, requests.exceptions.ChunkedEncodingError) or "IncompleteRead" in text \
                or "Connection broken" in text or "aborted" in text.lower():
            raise AssetError(f"download of {url} was interrupted{kept}",
                             "run the same command again: it resumes where it stopped") from None
        why = "connection refused" if "refused" in text.lower() else \
            "name not resolved (offline?)" if "resolve" in text.lower() or "getaddrinfo" in text.lower() else \
            "cannot connect"
        raise AssetError(f"cannot download {url}: {why}{kept}",
                         "check the network, or serve the archives yourself and pass --mirror URL "
                         f"(or set {MIRROR_ENV})") from None
    except requests.exceptions.Timeout:
        raise AssetError(f"cannot download {url}: timed out", "check the network and run the command again") from None
    except requests.exceptions.HTTPError as exc:
        code = exc.response.status_code if exc.response is not None else "?"
        raise AssetError(f"cannot download {url}: HTTP {code}",
                         "the archive is not served there; check --mirror / the registry URL") from None
    except requests.exceptions.RequestException as exc:
        raise AssetError(f"cannot download {url}: {type(exc).__name__}", "check the network and retry") from None
    except ValueError as exc:  # pooch: hash mismatch (the downloaded file is deleted)
        if "hash" in str(exc).lower():
            raise AssetError(f"{url}: sha256 mismatch (expected {source.sha256})",
                             "the download is corrupt or the upstream archive changed; the file was deleted, "
                             "run the command again or use a --mirror that serves the pinned archive") from None
        raise
    except OSError as exc:
        raise _disk_error(exc, downloads, "downloading") from None


def _convert_glb2obj(data: bytes, name: str) -> bytes:
    """A .glb visual as a Wavefront .obj (geometry only; trimesh comes with yourdfpy)."""
    import io

    import trimesh

    try:
        scene = trimesh.load(io.BytesIO(data), file_type="glb", force="mesh")
        return trimesh.exchange.obj.export_obj(scene, include_texture=False, include_normals=True).encode("utf-8")
    except Exception as exc:  # noqa: BLE001 (trimesh raises many kinds; one line naming the file)
        raise AssetError(f"{name}: cannot convert the .glb visual to .obj ({type(exc).__name__})",
                         "upgrade trimesh, or ignore: MuJoCo discards visuals when it simulates") from None


def _produce(raw: bytes, entry: FileEntry, where: str) -> bytes:
    if entry.source_sha256 is not None and hashlib.sha256(raw).hexdigest() != entry.source_sha256:
        raise AssetError(f"{where}: sha256 mismatch in the archive (expected {entry.source_sha256})",
                         "the archive is corrupt or not the pinned upstream commit; delete it from .downloads and retry")
    if entry.replace:
        text = raw.decode("utf-8")
        for old, new in entry.replace:
            text = text.replace(old, new)
        raw = text.encode("utf-8")
    if entry.convert == "glb2obj":
        raw = _convert_glb2obj(raw, where)
    return raw


def _extract(archive: Path, source: Source, wanted: dict[str, list[tuple[str, str, FileEntry]]], staging: Path,
             open_out: Callable = open) -> set[str]:
    """Read the ``wanted`` members (member → [(unit, path, entry)]) of ``archive`` into ``staging``; returns
    the members found."""
    found: set[str] = set()
    try:
        with tarfile.open(archive, "r|gz") as tar:
            for m in tar:
                if not m.name.startswith(source.prefix):
                    continue
                member = m.name[len(source.prefix):]
                if member not in wanted:
                    continue
                where = f"{archive.name}:{m.name}"
                try:
                    tarfile.data_filter(m, str(staging))  # refuses links, devices, absolute names, '..'
                except tarfile.FilterError as exc:
                    raise AssetError(f"{where}: refused ({type(exc).__name__})",
                                     "the archive is not the pinned upstream one; delete it from .downloads") from None
                if not m.isreg():
                    raise AssetError(f"{where}: not a regular file", "the archive is not the pinned upstream one")
                if m.size > MAX_MEMBER_BYTES:
                    raise AssetError(f"{where}: {m.size} bytes, more than {MAX_MEMBER_BYTES >> 20} MB",
                                     "the archive is not the pinned upstream one")
                src = tar.extractfile(m)
                edited = len(wanted[member]) > 1 or any(e.replace or e.convert or e.source_sha256
                                                        for _, _, e in wanted[member])
                raw = src.read(MAX_EDIT_BYTES + 1) if edited else None
                if raw is not None and len(raw) > MAX_EDIT_BYTES:
                    raise AssetError(f"{where}: too large to edit", "the archive is not the pinned upstream one")
                for unit, path, entry in wanted[member]:
                    out = staging / unit / path
                    out.parent.mkdir(parents=True, exist_ok=True)
                    try:
                        with open_out(out, "wb") as f:
                            if raw is None:
                                shutil.copyfileobj(src, f, CHUNK)
                            else:
                                f.write(_produce(raw, entry, where))
                    except AssetError:
                        raise
                    except OSError as exc:
                        raise _disk_error(exc, out, "extracting") from None
                found.add(member)
    except tarfile.TarError as exc:
        raise AssetError(f"{archive}: not a readable .tar.gz ({exc})",
                         f"delete {archive} and run the command again") from None
    except (EOFError, OSError) as exc:
        if isinstance(exc, OSError) and exc.errno is not None:
            raise _disk_error(exc, archive, "extracting") from None
        raise AssetError(f"{archive}: truncated or corrupt archive", f"delete {archive} and run the command again") from None
    return found


def _verify(root: Path, unit: str, files: dict[str, FileEntry]) -> list[str]:
    """Problems of ``root/unit`` against the registry (empty: every file there and every pinned sha256 equal)."""
    bad = []
    for path, entry in files.items():
        p = root / unit / path
        if not p.is_file() or p.is_symlink():
            bad.append(f"{unit}/{path}: missing")
        elif entry.sha256 is not None and sha256_file(p) != entry.sha256:
            bad.append(f"{unit}/{path}: sha256 mismatch (expected {entry.sha256})")
    return bad


def installed_ok(dest: Path, unit: str, registry: Registry) -> bool:
    return (dest / unit).is_dir() and not _verify(dest, unit, registry.units[unit].files)


def fetch(units: list[str], dest: Path | None = None, *, mirror: str | None = None, registry: Registry | None = None,
          force: bool = False, progress: bool = True, log: Callable[[str], None] = lambda s: None,
          open_out: Callable = open) -> FetchReport:
    """Install ``units`` (e.g. ``["hands/leap", "objects/ycb45"]``) into ``dest`` (default: the user's cache)."""
    registry = registry or shipped_registry()
    dest = Path(dest).expanduser() if dest is not None else default_asset_dir()
    report = FetchReport(dest=dest)
    try:
        dest.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _disk_error(exc, dest, "creating the destination") from None
    if not dest.is_dir():
        raise AssetError(f"--dest {dest} is not a folder", "name a folder (it is created if missing)")
    todo = []
    for unit in units:
        if not force and installed_ok(dest, unit, registry):
            report.already.append(unit)
        else:
            todo.append(unit)
    if not todo:
        _write_marker(dest, registry, report)
        return report
    by_source: dict[str, dict[str, list[tuple[str, str, FileEntry]]]] = {}
    for unit in todo:
        for path, entry in registry.units[unit].files.items():
            by_source.setdefault(entry.source, {}).setdefault(entry.member, []).append((unit, path, entry))
    downloads = dest / DOWNLOADS
    try:
        downloads.mkdir(exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".staging-", dir=dest))
    except OSError as exc:
        raise _disk_error(exc, dest, "preparing the download") from None
    try:
        for name, wanted in by_source.items():
            source = registry.sources[name]
            url = archive_url(source, mirror)
            log(f"{source.repo} @ {source.commit[:12]}: {url}")
            archive = download(source, url, downloads, progress)
            report.archives[archive.name] = sha256_file(archive)
            found = _extract(archive, source, wanted, staging, open_out)
            missing = sorted(set(wanted) - found)
            if missing:
                raise AssetError(f"{archive.name}: {len(missing)} file(s) missing, e.g. {source.prefix}{missing[0]}",
                                 f"the archive is not {source.repo} at {source.commit[:12]}; delete {archive} and retry")
        for unit in todo:
            bad = _verify(staging, unit, registry.units[unit].files)
            if bad:
                raise AssetError(f"{len(bad)} file(s) failed verification, first: {bad[0]}",
                                 "the archive is corrupt or not the pinned upstream commit; delete "
                                 f"{downloads} and run the command again")
        for unit in todo:  # one rename per unit: a unit is either all there (verified) or not there
            target = dest / unit
            try:
                target.parent.mkdir(parents=True, exist_ok=True)
                old = None
                if target.exists() or target.is_symlink():
                    old = staging / ".replaced" / unit
                    old.parent.mkdir(parents=True, exist_ok=True)
                    os.rename(target, old)
                os.rename(staging / unit, target)
            except OSError as exc:
                raise _disk_error(exc, target, "installing") from None
            report.installed.append(unit)
            report.files += len(registry.units[unit].files)
            log(f"installed {unit} ({len(registry.units[unit].files)} files verified)")
        _write_marker(dest, registry, report)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return report


def _write_marker(dest: Path, registry: Registry, report: FetchReport) -> None:
    marker = dest / ASSET_MARKER
    try:
        old = json.loads(marker.read_text(encoding="utf-8")) if marker.is_file() else {}
        units = old.get("units", {}) if isinstance(old, dict) and isinstance(old.get("units"), dict) else {}
    except (OSError, ValueError):
        units = {}
    for unit in report.installed + report.already:
        srcs = sorted({e.source for e in registry.units[unit].files.values()})
        units[unit] = {s: registry.sources[s].commit for s in srcs}
    text = json.dumps(dict(format=1, units=dict(sorted(units.items()))), indent=1) + "\n"
    from dgz_cli.spec.io import atomic_write

    atomic_write(marker, text)  # temp file + rename, umask-derived mode; a write error is one line naming it
