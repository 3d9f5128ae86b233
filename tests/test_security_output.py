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


@pytest.mark.parametrize("where", ["mkstemp", "fsync"])
@pytest.mark.parametrize("inherited", ["default", "ignored"])
def test_a_stop_signal_inside_a_write_lands_after_it(monkeypatch, tmp_path, where, inherited):
    """SIGTERM makes `dgz train` raise KeyboardInterrupt and save; a stop that arrived inside a periodic
    checkpoint's write (once between mkstemp creating the file and returning its name) left a .tmp behind.
    The stop now lands when the write is done, on the handler that was in place: Python's Ctrl-C handler raises
    then; an ignored SIGINT (a background job, nohup) stays ignored. Either way the file is whole and nothing
    else is in the folder. The handler is set here, not inherited, so the test means the same however it runs."""
    import signal
    import tempfile

    handler = signal.default_int_handler if inherited == "default" else signal.SIG_IGN
    real = {"mkstemp": tempfile.mkstemp, "fsync": os.fsync}[where]

    def stop_inside(*args, **kwargs):
        result = real(*args, **kwargs)
        signal.raise_signal(signal.SIGINT)
        return result

    monkeypatch.setattr(tempfile if where == "mkstemp" else os, where, stop_inside)
    before = signal.signal(signal.SIGINT, handler)
    try:
        if inherited == "default":
            with pytest.raises(KeyboardInterrupt):
                atomic_write_bytes(tmp_path / "model.safetensors", b"weights")
        else:
            atomic_write_bytes(tmp_path / "model.safetensors", b"weights")
        assert signal.getsignal(signal.SIGINT) is handler
    finally:
        signal.signal(signal.SIGINT, before)
    assert (tmp_path / "model.safetensors").read_bytes() == b"weights"
    assert _leftovers(tmp_path) == []


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


# --------------------------------------------------------------------------------------------
# dgz eval --json/--csv: unusable targets are refused before the evaluation runs
# --------------------------------------------------------------------------------------------

def _evaluate(monkeypatch, json_out=None, csv_out=None):
    from rich.console import Console

    from dgz_cli.cli import sim_cmd

    def never(*a, **k):
        raise AssertionError("the evaluation started before the output paths were checked")
    monkeypatch.setattr(sim_cmd, "_policy_factory", never)
    return sim_cmd.evaluate("scripted", ["dgz_tri"], "sphere", 1, 0, False, json_out, csv_out, None,
                            Console(record=True))


@pytest.mark.parametrize("option", ["json", "csv"])
@pytest.mark.parametrize("what, expect", [
    ("folder", "it exists and is a folder"),
    ("dev-null", "not a regular file"),
    ("fifo", "not a regular file"),
    ("symlink-to-folder", "it exists and is a folder"),
    ("parent-is-a-file", "(is not a folder|Not a directory)"),
    ("name-too-long", "(?i)file name too long"),
])
def test_eval_outputs_are_checked_before_the_evaluation(monkeypatch, tmp_path, option, what, expect):
    (tmp_path / "d").mkdir()
    (tmp_path / "file").write_text("x")
    if what == "fifo":
        os.mkfifo(tmp_path / "f")
    if what == "symlink-to-folder":
        (tmp_path / "link").symlink_to(tmp_path / "d")
    target = {"folder": tmp_path / "d", "dev-null": Path("/dev/null"), "fifo": tmp_path / "f",
              "symlink-to-folder": tmp_path / "link", "parent-is-a-file": tmp_path / "file" / "sub" / "r.json",
              "name-too-long": tmp_path / ("r" * 300 + ".json")}[what]
    kw = {f"{option}_out": target}
    with pytest.raises(DgzError, match=expect) as info:
        _evaluate(monkeypatch, **kw)
    assert str(target) in info.value.message and "\n" not in info.value.message
    assert os.path.exists("/dev/null") and not Path("/dev/null").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["d", "file"] + (["f"] if what == "fifo" else []) + (["link"] if what == "symlink-to-folder" else []))


def test_eval_same_json_and_csv_is_refused(monkeypatch, tmp_path):
    with pytest.raises(DgzError, match="--json and --csv name the same file"):
        _evaluate(monkeypatch, tmp_path / "r.out", tmp_path / "r.out")


def test_eval_good_targets_pass_the_check(monkeypatch, tmp_path):
    """A new file in a folder still to be created, and a symlink to a regular file, reach the evaluation."""
    (tmp_path / "old.json").write_text("{}")
    (tmp_path / "alias.json").symlink_to(tmp_path / "old.json")
    with pytest.raises(AssertionError, match="evaluation started"):
        _evaluate(monkeypatch, tmp_path / "new" / "deeper" / "r.json", tmp_path / "alias.json")


def test_eval_unwritable_folder_is_refused_before_the_evaluation(monkeypatch, tmp_path):
    """A folder the user cannot write to (or a read-only mount): root passes permission bits, so access(2)'s
    answer is simulated here; the next test checks the real thing as an unprivileged user."""
    ro = tmp_path / "ro"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **k: False if Path(p) == ro else real(p, mode, **k))
    with pytest.raises(DgzError, match=f"folder {ro} is not writable"):
        _evaluate(monkeypatch, csv_out=ro / "sub" / "r.csv")
    assert list(ro.iterdir()) == []


@pytest.mark.skipif(os.geteuid() == 0, reason="root passes permission bits")
def test_eval_unwritable_folder_is_refused_for_real(monkeypatch, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    os.chmod(ro, 0o555)
    try:
        with pytest.raises(DgzError, match=f"folder {ro} is not writable"):
            _evaluate(monkeypatch, json_out=ro / "r.json")
    finally:
        os.chmod(ro, 0o755)
