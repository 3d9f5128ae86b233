"""`dgz assets fetch`, offline: a bounded HTTP server on 127.0.0.1 serves fixture archives that the tests build
(from the built-in dgz_tri hand, or from a small part of DGZ_ASSET_ROOT laid out as the upstream archive is).

Covered: a fetched LEAP tree is byte-identical to the reference root and `dgz lint leap` passes on it from the
default (cache) destination without DGZ_ASSET_ROOT; YCB model.xml edits replay byte for byte; resume of a
partial download (HTTP Range); an interrupted download; archive and file sha256 mismatches; offline; a full
disk while downloading and while extracting; links in an archive; never a half-installed unit.
"""

from __future__ import annotations

import errno
import hashlib
import io
import json
import os
import subprocess
import sys
import tarfile
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest

from conftest import BUILTIN, REPO, SPECS, asset_root, needs_assets
from dgz_cli.assets import fetch as fetch_mod
from dgz_cli.assets.registry import Registry, load_registry, shipped_registry
from dgz_cli.spec.errors import AssetError

DGZ = str(Path(sys.executable).with_name("dgz"))
COMMIT = "0123456789abcdef0123456789abcdef01234567"


def sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


class _Handler(BaseHTTPRequestHandler):
    files: dict[str, bytes] = {}
    log: list[tuple[str, str | None, int]] = []
    cut_after: dict[str, int] = {}  # path → bytes sent before the connection is dropped (once)

    def do_GET(self):  # noqa: N802
        name = self.path.lstrip("/")
        data = self.files.get(name)
        rng = self.headers.get("Range")
        if data is None:
            self.log.append((name, rng, 404))
            self.send_error(404)
            return
        start = int(rng.split("=")[1].split("-")[0]) if rng else 0
        if start >= len(data) and rng:
            self.log.append((name, rng, 416))
            self.send_response(416)
            self.send_header("Content-Range", f"bytes */{len(data)}")
            self.end_headers()
            return
        body = data[start:]
        code = 206 if rng else 200
        self.log.append((name, rng, code))
        self.send_response(code)
        self.send_header("Content-Length", str(len(body)))
        if rng:
            self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
        self.end_headers()
        cut = self.cut_after.pop(name, None)
        if cut is not None:
            self.wfile.write(body[:cut])
            self.wfile.flush()
            self.close_connection = True
            return
        self.wfile.write(body)

    def log_message(self, *args):  # quiet
        pass


@pytest.fixture()
def server():
    """A loopback file server (bounded: each test stops it; requests time out after 10 s)."""
    _Handler.files, _Handler.log, _Handler.cut_after = {}, [], {}
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), _Handler)
    httpd.timeout = 10
    t = threading.Thread(target=httpd.serve_forever, kwargs=dict(poll_interval=0.05), daemon=True)
    t.start()
    yield httpd, f"http://127.0.0.1:{httpd.server_address[1]}/", _Handler
    httpd.shutdown()
    httpd.server_close()
    t.join(5)


def make_tar(members: dict[str, bytes], links: dict[str, str] | None = None) -> bytes:
    buf = io.BytesIO()
    with tarfile.open(fileobj=buf, mode="w:gz", compresslevel=1) as tar:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            info.mtime = 0
            tar.addfile(info, io.BytesIO(data))
        for name, target in (links or {}).items():
            info = tarfile.TarInfo(name)
            info.type = tarfile.SYMTYPE
            info.linkname = target
            tar.addfile(info)
    return buf.getvalue()


def tri_registry(tmp_path: Path, archive_sha: str | None = None, pad: bytes = b"") -> tuple[Path, dict[str, bytes]]:
    """A one-unit registry (hands/tri: the built-in URDF plus a pad file) and its archive's members."""
    urdf = (BUILTIN / "dgz_tri.urdf").read_bytes()
    prefix = f"tri-{COMMIT}/"
    members = {prefix + "robots/dgz_tri.urdf": urdf, prefix + "robots/pad.bin": pad, prefix + "README": b"other\n"}
    reg = dict(format=1, sources=dict(tri=dict(repo="dgz/tri", commit=COMMIT, licence="MIT", url="https://unused.invalid/x",
                                               archive=f"tri-{COMMIT}.tar.gz", prefix=prefix, sha256=archive_sha)),
               units={"hands/tri": dict(files={
                   "urdf/dgz_tri.urdf": dict(source="tri", member="robots/dgz_tri.urdf", sha256=sha(urdf)),
                   "urdf/pad.bin": dict(source="tri", member="robots/pad.bin", sha256=sha(pad))})})
    path = tmp_path / "registry.json"
    path.write_text(json.dumps(reg))
    return path, members


def run_dgz(*args: str, env_extra: dict | None = None, drop_asset_env: bool = True) -> subprocess.CompletedProcess:
    env = dict(os.environ, COLUMNS="200")
    if drop_asset_env:
        env.pop("DGZ_ASSET_ROOT", None)
    env.pop("DGZ_ASSET_MIRROR", None)
    env.update(env_extra or {})
    return subprocess.run([DGZ, *args], capture_output=True, text=True, env=env, timeout=300)


def one_line_error(proc: subprocess.CompletedProcess, *words: str) -> None:
    assert proc.returncode == 1, (proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr + proc.stdout
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), proc.stderr
    for w in words:
        assert w in lines[0], lines[0]


def leftovers(dest: Path) -> list[str]:
    return [p.name for p in dest.iterdir() if p.name.startswith(".staging")] if dest.is_dir() else []


# --- the shipped registry ---------------------------------------------------------------------------------------

def test_shipped_registry_pins_every_copied_file_and_every_shipped_urdf():
    reg = shipped_registry()
    assert set(reg.hands()) == {p.parent.name for p in SPECS.glob("*/spec.yaml")} - {"dgz_tri"}
    assert reg.object_sets() == ["ycb45"]
    assert len([p for p in reg.units["objects/ycb45"].files if p.endswith("/model.xml")]) == 45
    for unit in reg.units.values():
        for path, f in unit.files.items():
            assert f.sha256 is not None or f.convert == "glb2obj", path
            assert f.replace == () or f.source_sha256 is not None, path
    import yaml

    for spec in SPECS.glob("*/spec.yaml"):
        prov = yaml.safe_load(spec.read_text())["provenance"]
        if prov["urdf"].startswith("dgz://"):
            continue
        unit, _, rest = prov["urdf"].partition("/")[2].partition("/")
        entry = reg.units[f"hands/{unit}"].files[rest]
        assert entry.sha256 == prov["urdf_sha256"], spec  # `dgz lint` then sees the same URDF sha256


def test_registry_refuses_paths_that_leave_the_unit(tmp_path):
    path, _ = tri_registry(tmp_path)
    raw = json.loads(path.read_text())
    raw["units"]["hands/tri"]["files"]["../../evil"] = raw["units"]["hands/tri"]["files"]["urdf/pad.bin"]
    path.write_text(json.dumps(raw))
    with pytest.raises(AssetError, match="not a plain relative path"):
        load_registry(path)


@needs_assets()
def test_shipped_registry_matches_the_reference_root_byte_for_byte():
    """Every URDF and collision mesh the registry pins is the file of ../shared/assets (only visuals differ)."""
    root = asset_root()
    reg = shipped_registry()
    compared = 0
    for name, unit in reg.units.items():
        for path, f in unit.files.items():
            if f.sha256 is None or path.endswith("visual.obj"):
                continue
            assert sha((root / name / path).read_bytes()) == f.sha256, f"{name}/{path}"
            compared += 1
    assert compared > 300


# --- fetching from the loopback server ---------------------------------------------------------------------------

def upstream_members(registry: Registry, unit: str, root: Path, only: set[str] | None = None) -> dict[str, bytes]:
    """The archive members a unit needs, rebuilt from the reference root (edits inverted and checked)."""
    members = {}
    for path, f in registry.units[unit].files.items():
        if only is not None and path.split("/")[0] not in only:
            continue
        data = (root / unit / path).read_bytes()
        if f.replace:
            text = data.decode()
            for old, new in reversed(f.replace):
                text = text.replace(new, old)
            data = text.encode()
            assert sha(data) == f.source_sha256, path  # the registry's edit replays upstream → reference exactly
        members[registry.sources[f.source].prefix + f.member] = data
    return members


@needs_assets()
def test_fetch_leap_into_the_cache_then_lint_without_asset_root(server, tmp_path):
    httpd, url, handler = server
    reg = shipped_registry()
    src = reg.sources["dex-urdf"]
    handler.files[src.archive] = make_tar(upstream_members(reg, "hands/leap", asset_root()))
    env = {"XDG_CACHE_HOME": str(tmp_path / "cache")}
    proc = run_dgz("assets", "fetch", "--hands", "leap", "--objects", "none", "--mirror", url, "--quiet", env_extra=env)
    assert proc.returncode == 0, proc.stderr
    dest = tmp_path / "cache" / "dgz" / "assets"
    assert "asset root ready" in proc.stdout and "without DGZ_ASSET_ROOT" in proc.stdout
    ref = asset_root() / "hands" / "leap" / "urdf"
    got = sorted(p.relative_to(dest / "hands/leap/urdf") for p in (dest / "hands/leap/urdf").rglob("*") if p.is_file())
    assert got == sorted(p.relative_to(ref) for p in ref.rglob("*") if p.is_file())
    for rel in got:
        assert (dest / "hands/leap/urdf" / rel).read_bytes() == (ref / rel).read_bytes(), rel
    assert json.loads((dest / ".dgz-assets.json").read_text())["units"]["hands/leap"] == {"dex-urdf": src.commit}
    assert leftovers(dest) == []
    lint = run_dgz("lint", "leap", "--json", env_extra=env)
    assert lint.returncode == 0, lint.stdout + lint.stderr
    import yaml

    want = yaml.safe_load((SPECS / "leap" / "spec.yaml").read_text())["provenance"]["urdf_sha256"]
    assert sha((dest / "hands/leap/urdf/leap_hand_right.urdf").read_bytes()) == want
    n = len(handler.log)
    again = run_dgz("assets", "fetch", "--hands", "leap", "--objects", "none", "--mirror", url, "--quiet", env_extra=env)
    assert again.returncode == 0 and "already there and verified: hands/leap" in again.stdout
    assert len(handler.log) == n  # nothing downloaded


@needs_assets()
def test_fetch_ycb_objects_replays_the_model_edits(server, tmp_path):
    """Three YCB objects: collision hulls byte-identical, model.xml rebuilt from upstream's byte for byte, and
    the object loads in a scene. (Offline the upstream 16k visual is not at hand: the fixture serves the
    reference root's visual and the test registry pins that one.)"""
    httpd, url, handler = server
    reg = shipped_registry()
    names = {"025_mug", "011_banana", "065-a_cups"}
    unit = reg.units["objects/ycb45"]
    files = {}
    for path, f in unit.files.items():
        if path.split("/")[0] in names:
            if path.endswith("visual.obj"):
                f = f.model_copy(update=dict(sha256=sha((asset_root() / "objects/ycb45" / path).read_bytes())))
            files[path] = f
    small = reg.model_copy(update=dict(units={"objects/ycb45": unit.model_copy(update=dict(files=files))}))
    handler.files[reg.sources["YCB_Dataset"].archive] = make_tar(
        upstream_members(small, "objects/ycb45", asset_root()))
    dest = tmp_path / "assets"
    report = fetch_mod.fetch(["objects/ycb45"], dest, mirror=url, registry=small, progress=False)
    assert report.installed == ["objects/ycb45"] and report.files == len(files)
    for path in files:
        if not path.endswith("visual.obj"):
            assert (dest / "objects/ycb45" / path).read_bytes() == (asset_root() / "objects/ycb45" / path).read_bytes()
    from dgz_cli.sim.objects import object_spec, resolve_objects

    (obj,) = resolve_objects("025_mug", str(dest))
    assert object_spec(obj, visual=False).compile().nbody >= 2


def test_resume_of_a_partial_download(server, tmp_path):
    httpd, url, handler = server
    reg_path, members = tri_registry(tmp_path, pad=os.urandom(300_000))
    archive = make_tar(members)
    reg = load_registry(reg_path)
    src = reg.sources["tri"]
    handler.files[src.archive] = archive
    dest = tmp_path / "assets"
    (dest / ".downloads").mkdir(parents=True)
    half = len(archive) // 2
    (dest / ".downloads" / (src.archive + ".part")).write_bytes(archive[:half])
    report = fetch_mod.fetch(["hands/tri"], dest, mirror=url, registry=reg, progress=False)
    assert handler.log == [(src.archive, f"bytes={half}-", 206)]  # only the rest was asked for
    assert report.installed == ["hands/tri"]
    assert (dest / "hands/tri/urdf/dgz_tri.urdf").read_bytes() == (BUILTIN / "dgz_tri.urdf").read_bytes()
    assert (dest / ".downloads" / src.archive).read_bytes() == archive
    assert not (dest / ".downloads" / (src.archive + ".part")).exists()


def test_interrupted_download_is_one_line_then_resumes(server, tmp_path):
    httpd, url, handler = server
    reg_path, members = tri_registry(tmp_path, pad=os.urandom(300_000))
    archive = make_tar(members)
    src = load_registry(reg_path).sources["tri"]
    handler.files[src.archive] = archive
    handler.cut_after[src.archive] = 100_000
    dest = tmp_path / "assets"
    args = ("assets", "fetch", "--registry", str(reg_path), "--hands", "tri", "--objects", "none", "--dest", str(dest),
            "--mirror", url, "--quiet")
    one_line_error(run_dgz(*args), "interrupted", "resumes")
    kept = (dest / ".downloads" / (src.archive + ".part")).stat().st_size
    assert 0 < kept <= 100_000  # the whole chunks received before the cut
    assert not (dest / "hands").exists() and leftovers(dest) == []
    ok = run_dgz(*args)
    assert ok.returncode == 0, ok.stderr
    assert handler.log[-1] == (src.archive, f"bytes={kept}-", 206)
    assert (dest / "hands/tri/urdf/pad.bin").read_bytes() == members[f"tri-{COMMIT}/robots/pad.bin"]


def test_archive_sha_mismatch(server, tmp_path):
    httpd, url, handler = server
    reg_path, members = tri_registry(tmp_path, archive_sha="0" * 64)
    src = load_registry(reg_path).sources["tri"]
    handler.files[src.archive] = make_tar(members)
    dest = tmp_path / "assets"
    proc = run_dgz("assets", "fetch", "--registry", str(reg_path), "--hands", "tri", "--objects", "none",
                   "--dest", str(dest), "--mirror", url, "--quiet")
    one_line_error(proc, "sha256 mismatch", src.archive)
    assert not (dest / "hands").exists() and leftovers(dest) == []
    assert not (dest / ".downloads" / src.archive).exists()  # the bad download is not kept


def test_file_sha_mismatch_installs_nothing(server, tmp_path):
    httpd, url, handler = server
    reg_path, members = tri_registry(tmp_path)
    members[f"tri-{COMMIT}/robots/dgz_tri.urdf"] += b"<!-- tampered -->"
    src = load_registry(reg_path).sources["tri"]
    handler.files[src.archive] = make_tar(members)
    dest = tmp_path / "assets"
    proc = run_dgz("assets", "fetch", "--registry", str(reg_path), "--hands", "tri", "--objects", "none",
                   "--dest", str(dest), "--mirror", url, "--quiet")
    one_line_error(proc, "failed verification", "hands/tri/urdf/dgz_tri.urdf", "sha256 mismatch")
    assert not (dest / "hands").exists() and leftovers(dest) == [] and not (dest / ".dgz-assets.json").exists()


def test_offline_is_one_line(tmp_path):
    import socket

    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    reg_path, _ = tri_registry(tmp_path)
    dest = tmp_path / "assets"
    proc = run_dgz("assets", "fetch", "--registry", str(reg_path), "--hands", "tri", "--objects", "none",
                   "--dest", str(dest), "--mirror", f"http://127.0.0.1:{port}/", "--quiet")
    one_line_error(proc, "cannot download", f"127.0.0.1:{port}", "connection refused", "--mirror")
    assert not (dest / "hands").exists() and leftovers(dest) == []


def test_full_disk_while_extracting_leaves_no_half_tree(server, tmp_path):
    httpd, url, handler = server
    reg_path, members = tri_registry(tmp_path, pad=b"x" * 1000)
    reg = load_registry(reg_path)
    handler.files[reg.sources["tri"].archive] = make_tar(members)
    dest = tmp_path / "assets"

    class Full(io.BytesIO):
        def write(self, b):
            raise OSError(errno.ENOSPC, "No space left on device")

    def open_full(path, mode="r", *a, **k):
        return Full() if "pad.bin" in str(path) else open(path, mode, *a, **k)

    with pytest.raises(AssetError, match="no space left on the device while extracting"):
        fetch_mod.fetch(["hands/tri"], dest, mirror=url, registry=reg, progress=False, open_out=open_full)
    assert not (dest / "hands").exists() and leftovers(dest) == []
    # the archive itself was complete: the next run needs no download
    n = len(handler.log)
    assert fetch_mod.fetch(["hands/tri"], dest, mirror=url, registry=reg, progress=False).installed == ["hands/tri"]
    assert len(handler.log) == n


def test_full_disk_while_downloading_keeps_the_part(server, tmp_path, monkeypatch):
    httpd, url, handler = server
    reg_path, members = tri_registry(tmp_path, pad=os.urandom(200_000))
    reg = load_registry(reg_path)
    handler.files[reg.sources["tri"].archive] = make_tar(members)
    dest = tmp_path / "assets"
    real_open = open

    class Limited:
        def __init__(self, f):
            self.f, self.n = f, 0

        def write(self, b):
            if self.n + len(b) > 65536:
                raise OSError(errno.ENOSPC, "No space left on device")
            self.n += len(b)
            return self.f.write(b)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    monkeypatch.setattr(fetch_mod, "open", lambda p, m="r", *a, **k: Limited(real_open(p, m, *a, **k))
                        if str(p).endswith(".part") else real_open(p, m, *a, **k), raising=False)
    with pytest.raises(AssetError, match="no space left on the device while downloading"):
        fetch_mod.fetch(["hands/tri"], dest, mirror=url, registry=reg, progress=False)
    assert (dest / ".downloads" / (reg.sources["tri"].archive + ".part")).stat().st_size == 65536
    assert not (dest / "hands").exists() and leftovers(dest) == []


def test_links_in_the_archive_are_refused(server, tmp_path):
    httpd, url, handler = server
    reg_path, members = tri_registry(tmp_path)
    reg = load_registry(reg_path)
    del members[f"tri-{COMMIT}/robots/pad.bin"]
    handler.files[reg.sources["tri"].archive] = make_tar(members, links={f"tri-{COMMIT}/robots/pad.bin": "/etc/passwd"})
    dest = tmp_path / "assets"
    with pytest.raises(AssetError, match="refused|not a regular file"):
        fetch_mod.fetch(["hands/tri"], dest, mirror=url, registry=reg, progress=False)
    assert not (dest / "hands").exists() and leftovers(dest) == []


def test_force_replaces_a_unit_in_one_rename(server, tmp_path):
    httpd, url, handler = server
    reg_path, members = tri_registry(tmp_path)
    reg = load_registry(reg_path)
    handler.files[reg.sources["tri"].archive] = make_tar(members)
    dest = tmp_path / "assets"
    fetch_mod.fetch(["hands/tri"], dest, mirror=url, registry=reg, progress=False)
    (dest / "hands/tri/urdf/dgz_tri.urdf").write_text("broken")  # a damaged unit is fetched again
    report = fetch_mod.fetch(["hands/tri"], dest, mirror=url, registry=reg, progress=False)
    assert report.installed == ["hands/tri"]
    assert (dest / "hands/tri/urdf/dgz_tri.urdf").read_bytes() == (BUILTIN / "dgz_tri.urdf").read_bytes()
    assert sorted(p.name for p in dest.iterdir()) == [".dgz-assets.json", ".downloads", "hands"]


def test_unknown_hand_is_one_line(tmp_path):
    proc = run_dgz("assets", "fetch", "--hands", "nope", "--dest", str(tmp_path / "a"))
    one_line_error(proc, "--hands 'nope'", "leap")


def test_glb_visual_is_converted_and_its_source_checked(server, tmp_path):
    """Inspire's visuals: the .glb member is pinned by sha256 and converted to .obj (geometry kept)."""
    import trimesh

    httpd, url, handler = server
    glb = trimesh.creation.box(extents=(0.1, 0.2, 0.3)).export(file_type="glb")
    reg_path, members = tri_registry(tmp_path)
    raw = json.loads(reg_path.read_text())
    raw["units"]["hands/tri"]["files"]["urdf/meshes/visual/box.obj"] = dict(
        source="tri", member="robots/box.glb", source_sha256=sha(glb), convert="glb2obj")
    reg_path.write_text(json.dumps(raw))
    reg = load_registry(reg_path)
    handler.files[reg.sources["tri"].archive] = make_tar({**members, f"tri-{COMMIT}/robots/box.glb": glb})
    dest = tmp_path / "assets"
    fetch_mod.fetch(["hands/tri"], dest, mirror=url, registry=reg, progress=False)
    mesh = trimesh.load(dest / "hands/tri/urdf/meshes/visual/box.obj", force="mesh")
    assert np.allclose(mesh.extents, (0.1, 0.2, 0.3))
    handler.files[reg.sources["tri"].archive] = make_tar({**members, f"tri-{COMMIT}/robots/box.glb": glb + b"\0"})
    (dest / ".downloads" / reg.sources["tri"].archive).unlink()
    with pytest.raises(AssetError, match="sha256 mismatch in the archive"):
        fetch_mod.fetch(["hands/tri"], dest, mirror=url, registry=reg, progress=False, force=True)
    assert trimesh.load(dest / "hands/tri/urdf/meshes/visual/box.obj", force="mesh").vertices.shape[0] > 0  # kept
