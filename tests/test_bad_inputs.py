"""Bad-input corpus: every broken URDF/xacro/option/spec fails cleanly through the real CLI.

Each case runs ``python -m dgz_cli.cli.app ...`` in a subprocess with cwd=tmp_path and checks:
exit code != 0, no Python traceback, a one-line error that names the problem, and (for
``dgz onboard``) that no output spec and no stray atomic-write temp file was left behind.

The bad URDFs are small mutations of ``good_urdf()``: a primitive-only 2-finger hand
(palm box + two fingers of two revolute flexion joints each), which itself must onboard.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import yaml

CLI = [sys.executable, "-m", "dgz_cli.cli.app"]
TIMEOUT = 60  # per subprocess; a hang is a failure, not a stuck suite


# --------------------------------------------------------------------------------------------
# A tiny valid 2-finger hand, built from parts so each bad case can change one thing.
# --------------------------------------------------------------------------------------------

def _link(name: str, geom: str = '<box size="0.02 0.02 0.04"/>', z: float = 0.02, extra: str = "") -> str:
    return (f'  <link name="{name}">\n'
            f'    <inertial><origin xyz="0 0 {z}"/><mass value="0.02"/>'
            f'<inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial>\n'
            f'    <collision><origin xyz="0 0 {z}"/><geometry>{geom}</geometry></collision>{extra}\n'
            f'  </link>\n')


def _joint(name: str, parent: str, child: str, xyz: str, type_: str = "revolute",
           lower: str = "0", upper: str = "1.5", extra: str = "") -> str:
    limit = f'<limit lower="{lower}" upper="{upper}" effort="1" velocity="3"/>' if type_ != "fixed" else ""
    return (f'  <joint name="{name}" type="{type_}">\n'
            f'    <parent link="{parent}"/><child link="{child}"/>\n'
            f'    <origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="1 0 0"/>{limit}{extra}\n'
            f'  </joint>\n')


def good_urdf(*, joint_type: str = "revolute", b_j1_name: str = "b_j1", a_j1_limits: tuple[str, str] = ("0", "1.5"),
              palm_collision: str = "", b_j2_extra: str = "", body_extra: str = "", head: str = "",
              robot_open: str = '<robot name="two_finger">') -> str:
    parts = [_link("palm", '<box size="0.08 0.02 0.1"/>', 0.05, palm_collision)]
    for f, x in (("a", -0.02), ("b", 0.02)):
        lo, hi = a_j1_limits if f == "a" else ("0", "1.5")
        j1 = b_j1_name if f == "b" else "a_j1"
        parts += [_link(f"{f}_prox"), _joint(j1, "palm", f"{f}_prox", f"{x} 0 0.1", joint_type, lo, hi),
                  _link(f"{f}_dist"), _joint(f"{f}_j2", f"{f}_prox", f"{f}_dist", "0 0 0.04", joint_type,
                                             extra=b_j2_extra if f == "b" else "")]
    return f'<?xml version="1.0"?>\n{head}{robot_open}\n' + "".join(parts) + body_extra + "</robot>\n"


GOOD = good_urdf()

BILLION_LAUGHS = (
    '<!DOCTYPE robot [\n  <!ENTITY lol "lol">\n'
    + "".join(f'  <!ENTITY lol{i} "{("&lol" + (str(i - 1) if i > 1 else "") + ";") * 10}">\n' for i in range(1, 10))
    + "]>\n"
)

XACRO_NS = '<robot name="two_finger" xmlns:xacro="http://www.ros.org/wiki/xacro">'


# --------------------------------------------------------------------------------------------
# Running the CLI
# --------------------------------------------------------------------------------------------

def _env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("DGZ_ASSET_ROOT", None)  # bad cases must not depend on (or be masked by) the vendor asset root
    env["COLUMNS"] = "200"
    env["PYTHONUNBUFFERED"] = "1"
    return env


@dataclass
class Run:
    code: int
    stdout: str
    stderr: str
    seconds: float

    @property
    def text(self) -> str:
        return self.stdout + self.stderr


def dgz(cwd: Path, *args: str) -> Run:
    t0 = time.perf_counter()
    p = subprocess.run([*CLI, *args], cwd=cwd, env=_env(), capture_output=True, text=True, timeout=TIMEOUT)
    return Run(p.returncode, p.stdout, p.stderr, time.perf_counter() - t0)


def _describe(r: Run) -> str:
    return f"exit={r.code}\n--- stdout ---\n{r.stdout}\n--- stderr ---\n{r.stderr}"


def assert_no_traceback(r: Run) -> None:
    assert "Traceback" not in r.text, "a traceback escaped\n" + _describe(r)


def assert_nonzero_exit(r: Run) -> None:
    assert r.code != 0, "expected a non-zero exit\n" + _describe(r)


# --------------------------------------------------------------------------------------------
# The valid template onboards (the baseline every bad case mutates)
# --------------------------------------------------------------------------------------------

def test_good_template_onboards(tmp_path):
    (tmp_path / "good.urdf").write_text(GOOD)
    r = dgz(tmp_path, "onboard", "good.urdf", "-o", "good.yaml")
    assert r.code == 0, _describe(r)
    assert_no_traceback(r)
    spec = yaml.safe_load((tmp_path / "good.yaml").read_text())
    assert [row["joint"] for row in spec["joints"]] == ["a_j1", "a_j2", "b_j1", "b_j2"]
    assert not list(tmp_path.glob(".good.yaml.*")), "atomic-write temp file left behind"


# --------------------------------------------------------------------------------------------
# `dgz onboard` bad inputs
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Case:
    id: str
    files: dict[str, str]  # name (relative to tmp_path) → text
    args: tuple[str, ...]  # after `onboard`; "-o out.yaml" is appended
    expect: str | tuple[str, ...]  # distinctive substring(s) of the error line; a tuple means "any of"
    max_seconds: float | None = None
    xfail: str | None = None
    extra_checks: tuple[str, ...] = field(default=())


ONBOARD_CASES = [
    Case("malformed-xml", {"hand.urdf": GOOD.replace("</robot>", "</robo")}, ("hand.urdf",), "malformed XML"),
    # dgz refuses any DOCTYPE/ENTITY declaration before an XML parser (lxml or xacro's) sees the file.
    Case("entity-bomb", {"hand.urdf": good_urdf(head=BILLION_LAUGHS,
                                                  body_extra="  <bomb>&lol9;</bomb>\n")},
         ("hand.urdf",), "DOCTYPE/ENTITY declarations are not allowed", max_seconds=10.0),
    Case("entity-bomb-xacro", {"hand.xacro": good_urdf(head=BILLION_LAUGHS, robot_open=XACRO_NS,
                                                         body_extra="  <bomb>&lol9;</bomb>\n")},
         ("hand.xacro",), "DOCTYPE/ENTITY declarations are not allowed", max_seconds=10.0),
    Case("doctype-entity", {"hand.urdf": good_urdf(head='<!DOCTYPE robot [ <!ENTITY w "0.02"> ]>\n')},
         ("hand.urdf",), "ENTITY"),
    Case("missing-mesh", {"hand.urdf": good_urdf(
        palm_collision='\n    <collision><geometry><mesh filename="meshes/nope.stl"/></geometry></collision>')},
         ("hand.urdf",), "missing mesh"),
    Case("link-cycle", {"hand.urdf": good_urdf(body_extra=(
        _link("loop_a") + _link("loop_b")
        + _joint("j_ab", "loop_a", "loop_b", "0 0 0.01") + _joint("j_ba", "loop_b", "loop_a", "0 0 0.01")))},
         ("hand.urdf",), "loop"),
    Case("two-roots", {"hand.urdf": good_urdf(body_extra=_link("stray"))}, ("hand.urdf",), "root links"),
    Case("no-actuated-joint", {"hand.urdf": good_urdf(joint_type="fixed")}, ("hand.urdf",), "no actuated joint"),
    Case("duplicate-joint-name", {"hand.urdf": good_urdf(b_j1_name="a_j1")}, ("hand.urdf",),
         "duplicate joint name"),
    Case("duplicate-link-name", {"hand.urdf": good_urdf(body_extra=_link("a_prox"))}, ("hand.urdf",),
         "duplicate link name"),
    Case("nan-limit", {"hand.urdf": good_urdf(a_j1_limits=("nan", "1.5"))}, ("hand.urdf",), "is nan"),
    Case("inf-limit", {"hand.urdf": good_urdf(a_j1_limits=("0", "inf"))}, ("hand.urdf",), "is inf"),
    Case("non-numeric-limit", {"hand.urdf": good_urdf(a_j1_limits=("0", "abc"))}, ("hand.urdf",),
         "joint 'a_j1' limit upper is 'abc', not a number"),
    Case("broken-xacro", {"hand.xacro": good_urdf(robot_open=XACRO_NS,
                                                    body_extra='  <link name="${undefined_prop}"/>\n')},
         ("hand.xacro",), "xacro expansion failed", extra_checks=("undefined_prop",)),
    Case("mimic-missing-joint", {"hand.urdf": good_urdf(b_j2_extra='<mimic joint="no_such_joint"/>')},
         ("hand.urdf",), "mimics", extra_checks=("no_such_joint",)),
    Case("nonexistent-input", {}, ("nope.urdf",), "no such file"),
    Case("invalid-name", {"hand.urdf": GOOD}, ("hand.urdf", "--name", "Bad Name!"), "not a valid hand name"),
    Case("bad-xacro-arg", {"hand.urdf": GOOD}, ("hand.urdf", "--xacro-arg", "novalue"), "KEY=VALUE"),
    Case("overrides-unknown-key", {"hand.urdf": GOOD, "ov.yaml": "joinst:\n  a_j1:\n    reason: typo in key\n"},
         ("hand.urdf", "--overrides", "ov.yaml"), "unknown key", extra_checks=("joinst",)),
    Case("palm-link-missing", {"hand.urdf": GOOD}, ("hand.urdf", "--palm-link", "no_such_palm"),
         "is not a link", extra_checks=("no_such_palm",)),
]


def _params(cases):
    return [pytest.param(c, id=c.id, marks=[pytest.mark.xfail(strict=True, reason=c.xfail)] if c.xfail else [])
            for c in cases]


@pytest.mark.parametrize("case", _params(ONBOARD_CASES))
def test_onboard_rejects(case: Case, tmp_path: Path):
    for name, text in case.files.items():
        (tmp_path / name).write_text(text)
    r = dgz(tmp_path, "onboard", *case.args, "-o", "out.yaml")
    assert_no_traceback(r)
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert lines, "no line starting with 'error:' on stderr\n" + _describe(r)
    expect = (case.expect,) if isinstance(case.expect, str) else case.expect
    assert any(e in ln for e in expect for ln in lines), f"error line does not say {expect!r}\n" + _describe(r)
    for s in case.extra_checks:
        assert any(s in ln for ln in lines), f"error line does not name {s!r}\n" + _describe(r)
    assert not (tmp_path / "out.yaml").exists(), "output spec written despite the error"
    stray = sorted(p.name for p in tmp_path.glob(".out.yaml.*"))
    assert not stray, f"atomic-write temp files left behind: {stray}"
    if case.max_seconds is not None:
        assert r.seconds < case.max_seconds, f"took {r.seconds:.1f}s (entities expanded?)"
    assert_nonzero_exit(r)


def test_onboard_spec_failing_lint_is_not_written(tmp_path: Path):
    """Overrides that reverse a finger's flexion make the fresh spec fail the functional check."""
    (tmp_path / "hand.urdf").write_text(GOOD)
    (tmp_path / "ov.yaml").write_text("joints:\n  a_j1: {sign: -1, reason: wrong on purpose}\n"
                                      "  a_j2: {sign: -1, reason: wrong on purpose}\n")
    r = dgz(tmp_path, "onboard", "hand.urdf", "--overrides", "ov.yaml", "-o", "out.yaml")
    assert_no_traceback(r)
    assert any(ln.startswith("error") and "functional check" in ln for ln in r.stdout.splitlines()), _describe(r)
    assert "out.yaml was not written" in r.stdout, _describe(r)
    assert not (tmp_path / "out.yaml").exists(), "output spec written despite the lint error"
    assert not list(tmp_path.glob(".out.yaml.*")), "atomic-write temp file left behind"
    assert_nonzero_exit(r)


# --------------------------------------------------------------------------------------------
# `dgz lint` on tampered specs
# --------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def good_spec(tmp_path_factory) -> dict:
    """A valid spec onboarded once from the template (its provenance.urdf is an absolute path)."""
    d = tmp_path_factory.mktemp("good")
    (d / "good.urdf").write_text(GOOD)
    r = dgz(d, "onboard", "good.urdf", "-o", "good.yaml")
    assert r.code == 0, _describe(r)
    lint = dgz(d, "lint", "good.yaml")
    assert lint.code == 0, "the untampered spec must lint clean\n" + _describe(lint)
    return yaml.safe_load((d / "good.yaml").read_text())


def _unknown_key(s: dict) -> dict:
    s["colour"] = "red"
    return s


def _drop_first_joint(s: dict) -> dict:
    row = s["joints"].pop(0)
    node = next(n for n in s["nodes"] if n["id"] == row["node"])
    node["joints"].remove(row["joint"])
    return s


def _flip_mask(s: dict) -> dict:
    nid = next(iter(s["activation_mask"]))
    s["activation_mask"][nid][0] = 1 - s["activation_mask"][nid][0]
    return s


def _feature_out_of_range(s: dict) -> dict:
    nid = next(iter(s["features"]["values"]))
    s["features"]["values"][nid][0] = 5.0
    return s


def _schema_99(s: dict) -> dict:
    s["schema_version"] = 99
    return s


LINT_CASES = [
    pytest.param(_unknown_key, "unknown key", id="unknown-top-level-key"),
    pytest.param(_drop_first_joint, "missing from M_h", id="joint-missing-from-M_h"),
    pytest.param(_flip_mask, "mask row", id="mask-row-flipped"),
    pytest.param(_feature_out_of_range, "outside its normalization", id="feature-out-of-range"),
    pytest.param(": : :\n- [", "malformed YAML", id="not-yaml"),
    pytest.param(_schema_99, "schema_version", id="schema-version-99"),
]


def _lint_error_lines(r: Run) -> list[str]:
    return [ln for ln in r.stdout.splitlines() if ln[:1].isspace() and ln.strip().startswith("error")]


@pytest.mark.parametrize("tamper, expect", LINT_CASES)
def test_lint_rejects_tampered_spec(tamper, expect: str, good_spec: dict, tmp_path: Path):
    if isinstance(tamper, str):
        (tmp_path / "bad.yaml").write_text(tamper)
    else:
        import copy

        (tmp_path / "bad.yaml").write_text(yaml.safe_dump(tamper(copy.deepcopy(good_spec)), sort_keys=False))
    before = (tmp_path / "bad.yaml").read_bytes()
    r = dgz(tmp_path, "lint", "bad.yaml")
    assert_no_traceback(r)
    assert any(ln.startswith("FAIL") and "bad.yaml" in ln for ln in r.stdout.splitlines()), _describe(r)
    lines = _lint_error_lines(r)
    assert lines, "no indented 'error' line\n" + _describe(r)
    assert any(expect in ln for ln in lines), f"no error line says {expect!r}\n" + _describe(r)
    assert (tmp_path / "bad.yaml").read_bytes() == before, "lint modified the spec"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.yaml"], "lint created files"
    assert_nonzero_exit(r)


def test_lint_missing_spec_file(tmp_path: Path):
    r = dgz(tmp_path, "lint", "no_such.yaml")
    assert_no_traceback(r)
    lines = _lint_error_lines(r)
    assert any("no such" in ln and "no_such.yaml" in ln for ln in lines), _describe(r)
    assert list(tmp_path.iterdir()) == [], "lint created files"
    assert_nonzero_exit(r)


# --------------------------------------------------------------------------------------------
# Paths and reads: provenance.urdf and object names stay inside their root; only bounded regular files
# --------------------------------------------------------------------------------------------

def _provenance(reference: str):
    def tamper(s: dict) -> dict:
        s["provenance"]["urdf"] = reference
        return s
    return tamper


def _make_root(tmp_path: Path) -> Path:
    root = tmp_path / "assets"
    (root / "hands" / "h").mkdir(parents=True)
    (root / "objects" / "ycb45" / "ok").mkdir(parents=True)
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "secret.urdf").write_text(GOOD.replace("two_finger", "SECRET_OUTSIDE"))
    (tmp_path / "outside" / "model.xml").write_text("<mujoco/>")
    return root


PROVENANCE_CASES = [
    pytest.param("../outside/secret.urdf", "leaves the asset root", id="dotdot-out-of-asset-root"),
    pytest.param("hands/h/../../../outside/secret.urdf", "leaves the asset root", id="dotdot-inside-then-out"),
    pytest.param("dgz://hands/../../../../../etc/passwd", "leaves the package", id="dgz-uri-dotdot"),
    pytest.param("dgz://hands/../..", "leaves the package", id="dgz-uri-dotdot-folder"),
    pytest.param("/dev/zero", "not a regular file", id="dev-zero"),
    pytest.param("FIFO", "not a regular file", id="fifo"),
    pytest.param("hands", "not a regular file", id="a-folder"),
    pytest.param("hands/h/nope.urdf", "not found", id="missing-under-root"),
]


@pytest.mark.parametrize("reference, expect", PROVENANCE_CASES)
def test_lint_refuses_bad_provenance_path(reference: str, expect: str, good_spec: dict, tmp_path: Path):
    import copy

    root = _make_root(tmp_path)
    if reference == "FIFO":
        reference = str(tmp_path / "fifo.urdf")
        os.mkfifo(reference)
    bad = _provenance(reference)(copy.deepcopy(good_spec))
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(bad, sort_keys=False))
    # lint reports an unusable URDF as a warning ("URDF not checked"); it must name the refusal
    r = dgz(tmp_path, "lint", "bad.yaml", "--asset-root", str(root))
    assert_no_traceback(r)
    assert r.seconds < 30, f"took {r.seconds:.1f}s (blocked on a FIFO or an endless read?)"
    assert expect in r.text, _describe(r)
    assert "SECRET_OUTSIDE" not in r.text
    # a command that needs the URDF fails with one line
    r = dgz(tmp_path, "scene", "--hand", "bad.yaml", "--object", "sphere", "-o", "scene.xml", "--asset-root", str(root))
    assert_no_traceback(r)
    assert r.seconds < 30, f"took {r.seconds:.1f}s (blocked on a FIFO or an endless read?)"
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and expect in lines[0], _describe(r)
    assert "SECRET_OUTSIDE" not in r.text and not (tmp_path / "scene.xml").exists()
    assert_nonzero_exit(r)


@pytest.mark.parametrize("name", ["../../../outside", "../ycb45/../../../outside", "/tmp", "ok/../../../outside",
                                  ".."])
def test_scene_refuses_object_names_outside_the_asset_root(name: str, tmp_path: Path):
    root = _make_root(tmp_path)
    r = dgz(tmp_path, "scene", "--hand", "dgz_tri", "--object", name, "-o", "scene.xml", "--asset-root", str(root))
    assert_no_traceback(r)
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and "not a plain folder name" in lines[0], _describe(r)
    assert not (tmp_path / "scene.xml").exists()
    assert_nonzero_exit(r)


def test_object_model_must_be_a_regular_file(tmp_path: Path):
    from dgz_cli.sim.objects import resolve_objects
    from dgz_cli.spec.errors import AssetError

    root = _make_root(tmp_path)
    (root / "objects" / "ycb45" / "dir" / "model.xml").mkdir(parents=True)
    with pytest.raises(AssetError, match="not a regular file"):
        resolve_objects("dir", str(root))
    os.mkfifo(root / "objects" / "ycb45" / "ok" / "model.xml")
    with pytest.raises(AssetError, match="not a regular file"):
        resolve_objects("ok", str(root))


@pytest.mark.parametrize("what", ["dev-zero", "fifo", "folder", "huge"])
def test_onboard_and_lint_refuse_non_regular_or_huge_inputs(what: str, tmp_path: Path):
    if what == "dev-zero":
        target = "/dev/zero"
    elif what == "fifo":
        target = str(tmp_path / "hand.urdf")
        os.mkfifo(target)
    elif what == "folder":
        target = str(tmp_path / "d.urdf")
        os.mkdir(target)
    else:
        target = str(tmp_path / "big.urdf")
        with open(target, "wb") as fh:  # sparse: 65 MB of nothing
            fh.truncate(65 * 1024 * 1024)
    r = dgz(tmp_path, "onboard", target, "-o", "out.yaml")
    assert_no_traceback(r)
    assert r.seconds < 30, f"took {r.seconds:.1f}s"
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(lines) == 1 and ("not a regular file" in lines[0] or "MB dgz reads" in lines[0]), _describe(r)
    assert not (tmp_path / "out.yaml").exists()
    assert_nonzero_exit(r)
    r = dgz(tmp_path, "lint", target)  # the same file as a spec
    assert_no_traceback(r)
    assert r.seconds < 30, f"took {r.seconds:.1f}s"
    assert any(ln.startswith("FAIL") for ln in r.stdout.splitlines()), _describe(r)
    assert_nonzero_exit(r)


# --------------------------------------------------------------------------------------------
# Terminal output: rich markup and :emoji: codes inside names from input files print literally
# --------------------------------------------------------------------------------------------

def _rename(obj, old: str, new: str):
    """Every string (value or key) equal to ``old`` becomes ``new``: a consistent rename of a node or joint."""
    if isinstance(obj, dict):
        return {(new if k == old else k): _rename(v, old, new) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_rename(v, old, new) for v in obj]
    return new if obj == old else obj


MARKUP_NAMES = ["[link=file:///etc/passwd]f0[/link]", ":x:", "[bold red]loud[/]", "[/]", ":thumbs_up:x",
                "\\[b]x"]


@pytest.mark.parametrize("name", MARKUP_NAMES)
@pytest.mark.parametrize("what", ["joint", "node", "palm-link"])
def test_show_prints_names_from_the_spec_literally(what: str, name: str, good_spec: dict, tmp_path: Path):
    import copy

    spec = copy.deepcopy(good_spec)
    if what == "joint":
        spec = _rename(spec, spec["joints"][0]["joint"], name)
    elif what == "node":
        spec = _rename(spec, next(n["id"] for n in spec["nodes"] if n["parent"] is not None), name)
    else:
        spec["palm"]["link"] = name
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(spec, sort_keys=False))
    r = dgz(tmp_path, "show", "s.yaml")
    assert r.code == 0, _describe(r)
    assert_no_traceback(r)
    assert name in r.stdout, f"{name!r} not printed literally\n" + _describe(r)
    assert "❌" not in r.stdout and "👍" not in r.stdout and "\x1b]8;" not in r.stdout, _describe(r)


@pytest.mark.parametrize("name", [":x:", "[bold]b_j1[/bold]"])
def test_onboard_summary_prints_urdf_names_literally(name: str, tmp_path: Path):
    (tmp_path / "hand.urdf").write_text(good_urdf(b_j1_name=name))
    r = dgz(tmp_path, "onboard", "hand.urdf", "-o", "out.yaml")
    assert_no_traceback(r)
    assert name in r.stdout and "❌" not in r.text, _describe(r)
