"""Output paths (issue 10, item 6): never replace a device, FIFO or folder; write through symlinks;
never overwrite the input; an OSError is one line naming the path and leaves nothing behind."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import atomic_write_bytes
from test_bad_inputs import GOOD, _describe, assert_no_traceback, dgz


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


def test_refuses_fifo_and_folder(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(DgzError, match="not a regular file"):
        atomic_write_bytes(fifo, b"x")
    assert fifo.is_fifo()
    (tmp_path / "d").mkdir()
    with pytest.raises(DgzError, match="a folder"):
        atomic_write_bytes(tmp_path / "d", b"x")
    assert (tmp_path / "d").is_dir() and _leftovers(tmp_path) == []


def test_refuses_device_nodes_without_touching_them():
    for dev in ("/dev/null", "/dev/full", "/dev/zero"):
        if not os.path.exists(dev):
            continue
        before = os.stat(dev)
        with pytest.raises(DgzError, match="not a regular file"):
            atomic_write_bytes(Path(dev), b"x")
        after = os.stat(dev)
        assert (after.st_ino, after.st_mode, after.st_rdev) == (before.st_ino, before.st_mode, before.st_rdev)


def test_writes_through_symlinks(tmp_path):
    real = tmp_path / "real.yaml"
    real.write_text("old")
    link = tmp_path / "link.yaml"
    link.symlink_to(real)
    atomic_write_bytes(link, b"new")
    assert link.is_symlink() and real.read_text() == "new"
    dangling = tmp_path / "dangling.yaml"
    dangling.symlink_to(tmp_path / "sub" / "target.yaml")
    atomic_write_bytes(dangling, b"made")
    assert dangling.is_symlink() and (tmp_path / "sub" / "target.yaml").read_text() == "made"


def test_refuses_to_overwrite_an_input(tmp_path):
    src = tmp_path / "hand.urdf"
    src.write_text("urdf")
    alias = tmp_path / "alias.urdf"
    alias.symlink_to(src)
    for out in (src, alias, tmp_path / "." / "hand.urdf"):
        with pytest.raises(DgzError, match="is the input file"):
            atomic_write_bytes(out, b"spec", inputs=(src,))
    assert src.read_text() == "urdf"


@pytest.mark.parametrize("what", ["parent-is-a-file", "name-too-long"])
def test_os_errors_are_one_line(what, tmp_path):
    (tmp_path / "file").write_text("x")
    out = tmp_path / "file" / "out.yaml" if what == "parent-is-a-file" else tmp_path / ("a" * 300 + ".yaml")
    with pytest.raises(DgzError) as info:
        atomic_write_bytes(out, b"x")
    assert "cannot write" in info.value.message and "\n" not in str(info.value)
    assert _leftovers(tmp_path) == []


def test_onboard_output_equal_to_input_is_refused(tmp_path):
    (tmp_path / "hand.urdf").write_text(GOOD)
    r = dgz(tmp_path, "onboard", "hand.urdf", "-o", "hand.urdf")
    assert_no_traceback(r)
    assert r.code != 0, _describe(r)
    assert "is the input file" in r.stderr, _describe(r)
    assert (tmp_path / "hand.urdf").read_text() == GOOD


@pytest.mark.parametrize("target", ["fifo", "folder"])
def test_onboard_output_to_a_non_regular_file_is_refused(target, tmp_path):
    (tmp_path / "hand.urdf").write_text(GOOD)
    out = tmp_path / "out"
    os.mkfifo(out) if target == "fifo" else out.mkdir()
    r = dgz(tmp_path, "onboard", "hand.urdf", "-o", "out")
    assert_no_traceback(r)
    assert r.code != 0, _describe(r)
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "cannot write" in lines[0], _describe(r)
    assert out.is_fifo() if target == "fifo" else out.is_dir()


def test_show_png_never_replaces_a_device_or_fifo(tmp_path):
    """`dgz show --png` used its own temp-file + rename: /dev/full was replaced when run as root."""
    import pytest as _pytest

    from dgz_cli.spec.catalog import resolve_spec, resolve_urdf
    from dgz_cli.spec.io import load_spec
    from dgz_cli.viz import show

    fifo = tmp_path / "pic.png"
    os.mkfifo(fifo)
    spec = load_spec(resolve_spec("dgz_tri"))
    import inspect

    params = list(inspect.signature(show.render_png).parameters)
    if params[:2] == ["spec", "urdf_path"]:
        call = lambda out: show.render_png(spec, resolve_urdf(spec.provenance.urdf), out)  # noqa: E731
    else:  # (spec, kin, poser, out): the caller composes the kinematics
        from dgz_cli.onboard.compile import Poser, compile_model
        from dgz_cli.onboard.urdf import load_kinematics

        kin = load_kinematics(resolve_urdf(spec.provenance.urdf), spec.provenance.xacro_args)
        poser = Poser(kin, compile_model(kin))
        call = lambda out: show.render_png(spec, kin, poser, out)  # noqa: E731
    with _pytest.raises(DgzError, match="not a regular file"):
        call(fifo)
    assert fifo.is_fifo() and _leftovers(tmp_path) == []
    call(tmp_path / "ok.png")
    assert (tmp_path / "ok.png").read_bytes()[:4] == b"\x89PNG"
