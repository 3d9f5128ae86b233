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


# --------------------------------------------------------------------------------------------
# Output paths: -o equal to the input, unwritable targets, failed runs leave nothing behind
# --------------------------------------------------------------------------------------------

def _error_lines(r: Run) -> list[str]:
    return [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]


def assert_one_line_error(r: Run, *expect: str) -> str:
    assert_no_traceback(r)
    assert_nonzero_exit(r)
    lines = _error_lines(r)
    assert len(lines) == 1, "expected exactly one 'error:' line\n" + _describe(r)
    for e in expect:
        assert e in lines[0], f"the error line does not say {e!r}\n" + _describe(r)
    return lines[0]


@pytest.mark.parametrize("how", ["same-name", "through-symlink", "relative-dotted"])
def test_onboard_refuses_output_equal_to_the_input(how: str, tmp_path: Path):
    (tmp_path / "hand.urdf").write_text(GOOD)
    target = {"same-name": "hand.urdf", "relative-dotted": "./sub/../hand.urdf", "through-symlink": "link.yaml"}[how]
    (tmp_path / "sub").mkdir()
    if how == "through-symlink":
        os.symlink("hand.urdf", tmp_path / "link.yaml")
    r = dgz(tmp_path, "onboard", "hand.urdf", "-o", target)
    assert_one_line_error(r, "input")
    assert (tmp_path / "hand.urdf").read_text() == GOOD, "the input URDF was overwritten"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")], "temp files left behind"


LONG = "x" * 300 + ".out"
BAD_TARGETS = {"a-folder": "adir", "dev-full": "/dev/full", "too-long-name": LONG}


def _bad_target(tmp_path: Path, kind: str) -> str:
    (tmp_path / "adir").mkdir(exist_ok=True)
    return BAD_TARGETS[kind]


def _listing(tmp_path: Path) -> list[str]:
    return sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))


@pytest.mark.parametrize("kind", list(BAD_TARGETS))
def test_onboard_unwritable_output_is_one_line(kind: str, tmp_path: Path):
    (tmp_path / "hand.urdf").write_text(GOOD)
    target = _bad_target(tmp_path, kind)
    before = _listing(tmp_path)
    r = dgz(tmp_path, "onboard", "hand.urdf", "-o", target)
    assert_one_line_error(r, "cannot write")
    assert _listing(tmp_path) == before, "something was left behind"


@pytest.mark.parametrize("kind", list(BAD_TARGETS))
def test_scene_unwritable_output_is_one_line(kind: str, tmp_path: Path):
    target = _bad_target(tmp_path, kind)
    r = dgz(tmp_path, "scene", "--hand", "dgz_tri", "--object", "sphere", "-o", target)
    assert_one_line_error(r, "cannot write")
    assert _listing(tmp_path) == ["adir"]


@pytest.mark.parametrize("kind", list(BAD_TARGETS))
def test_show_png_unwritable_output_is_one_line(kind: str, tmp_path: Path):
    target = _bad_target(tmp_path, kind)
    r = dgz(tmp_path, "show", "dgz_tri", "--png", target)
    assert_one_line_error(r, "cannot write")
    assert _listing(tmp_path) == ["adir"]


@pytest.mark.parametrize("option", ["--json", "--csv"])
@pytest.mark.parametrize("kind", list(BAD_TARGETS))
def test_eval_unwritable_output_is_one_line(kind: str, option: str, tmp_path: Path):
    target = _bad_target(tmp_path, kind)
    r = dgz(tmp_path, "eval", "--hand", "dgz_tri", "--objects", "sphere", "--trials", "1", option, target)
    assert_one_line_error(r, "cannot write")
    assert _listing(tmp_path) == ["adir"]


@pytest.mark.parametrize("kind", list(BAD_TARGETS))
def test_deploy_unwritable_log_is_one_line(kind: str, tmp_path: Path):
    target = _bad_target(tmp_path, kind)
    r = dgz(tmp_path, "deploy", "--hand", "sim", "--policy", "scripted", "--log", target)
    assert_one_line_error(r, "--log")
    assert _listing(tmp_path) == ["adir"]


@pytest.mark.parametrize("kind", ["a-file", "under-dev-full", "too-long-name"])
def test_train_unusable_out_is_one_line_and_nothing_is_built(kind: str, tmp_path: Path):
    (tmp_path / "afile").write_text("keep me")
    target = {"a-file": "afile", "under-dev-full": "/dev/full/run", "too-long-name": LONG}[kind]
    r = dgz(tmp_path, "train", "--hands", "dgz_tri", "--objects", "sphere", "--iterations", "1", "--out", target)
    assert_one_line_error(r, "--out")
    assert r.seconds < 30, f"took {r.seconds:.1f}s: the env was built before the --out check"
    assert _listing(tmp_path) == ["afile"] and (tmp_path / "afile").read_text() == "keep me"


# --------------------------------------------------------------------------------------------
# Schema validation: eval --table files, --replay step logs, history.jsonl on --resume
# --------------------------------------------------------------------------------------------

GOOD_TABLE = {"policy": "p", "training_hands": ["a"], "hands": {"a": {"success_rate": 0.5, "episodes": 10},
                                                                "b": {"success_rate": 0.25, "episodes": 10}}}


def _table_with(**change) -> str:
    import copy
    import json

    data = copy.deepcopy(GOOD_TABLE)
    for key, value in change.items():
        if key == "rate_a":
            data["hands"]["a"]["success_rate"] = value
        elif key == "episodes_a":
            data["hands"]["a"]["episodes"] = value
        elif value is ...:
            del data[key]
        else:
            data[key] = value
    return json.dumps(data)


TABLE_CASES = [
    pytest.param("not json {", "not JSON", id="not-json"),
    pytest.param("", "not JSON", id="empty"),
    pytest.param("[1, 2]", "top level", id="top-level-list"),
    pytest.param('"text"', "top level", id="top-level-string"),
    pytest.param(_table_with(hands=...), "'hands'", id="no-hands"),
    pytest.param(_table_with(hands=[1, 2]), "'hands'", id="hands-is-a-list"),
    pytest.param(_table_with(hands={"a": 0.5}), "'hands.a'", id="hand-is-a-number"),
    pytest.param(_table_with(rate_a=float("nan")).replace("NaN", "NaN"), "success_rate", id="rate-nan"),
    pytest.param(_table_with(rate_a=float("inf")), "success_rate", id="rate-inf"),
    pytest.param(_table_with(rate_a=5.0), "success_rate", id="rate-above-1"),
    pytest.param(_table_with(rate_a=-0.1), "success_rate", id="rate-negative"),
    pytest.param(_table_with(rate_a="high"), "success_rate", id="rate-a-string"),
    pytest.param(_table_with(rate_a=None), "success_rate", id="rate-null"),
    pytest.param(_table_with(episodes_a=-3), "episodes", id="episodes-negative"),
    pytest.param(_table_with(training_hands="a"), "training_hands", id="training-hands-a-string"),
    pytest.param(_table_with(training_hands=[{"x": 1}]), "training_hands", id="training-hands-objects"),
    pytest.param(_table_with(policy="p" * 500), "policy", id="policy-name-huge"),
    pytest.param(_table_with(policy=["x"]), "policy", id="policy-a-list"),
    pytest.param("[" * 100000 + "]" * 100000, "not JSON", id="deeply-nested"),
]


@pytest.mark.parametrize("text, expect", TABLE_CASES)
def test_eval_table_refuses_bad_result_files(text: str, expect: str, tmp_path: Path):
    (tmp_path / "good.json").write_text(json_dumps(GOOD_TABLE))
    (tmp_path / "bad.json").write_text(text)
    r = dgz(tmp_path, "eval", "--table", "good.json", "--table", "bad.json")
    line = assert_one_line_error(r, "bad.json", expect)
    assert "[" * 50 not in line


@pytest.mark.parametrize("what", ["folder", "dev-zero", "missing", "fifo"])
def test_eval_table_refuses_non_regular_files(what: str, tmp_path: Path):
    target = {"folder": "d", "dev-zero": "/dev/zero", "missing": "nope.json", "fifo": "f.json"}[what]
    if what == "folder":
        (tmp_path / "d").mkdir()
    if what == "fifo":
        os.mkfifo(tmp_path / "f.json")
    r = dgz(tmp_path, "eval", "--table", target)
    assert_one_line_error(r, target)
    assert r.seconds < 30


def test_eval_table_accepts_a_good_file(tmp_path: Path):
    (tmp_path / "good.json").write_text(json_dumps(GOOD_TABLE))
    r = dgz(tmp_path, "eval", "--table", "good.json")
    assert r.code == 0, _describe(r)
    assert "0.50" in r.stdout


def json_dumps(obj) -> str:
    import json

    return json.dumps(obj)


HEADER = {"type": "header", "hand": "sim", "spec": "dgz_tri", "joints": ["j0", "j1"], "rate_hz": 20.0}


def _log(*records) -> str:
    import json

    return "".join((r if isinstance(r, str) else json.dumps(r)) + "\n" for r in records)


def _step(**fields) -> dict:
    return {"type": "step", "k": 0, "phase": "grasp", "target": [0.1, 0.2], "measured": [0.1, 0.2], **fields}


REPLAY_CASES = [
    pytest.param(_log("not json"), "not a JSON line", id="not-json"),
    pytest.param("", "no header", id="empty"),
    pytest.param(_log(_step()), "before the header", id="step-before-header"),
    pytest.param(_log([1, 2]), "not a step-log record", id="record-a-list"),
    pytest.param(_log({"type": "weird"}), "not a step-log record", id="unknown-type"),
    pytest.param(_log({"k": 1}), "not a step-log record", id="no-type"),
    pytest.param(_log({**HEADER, "joints": []}), "joints", id="header-no-joints"),
    pytest.param(_log({**HEADER, "joints": "j0"}), "joints", id="header-joints-a-string"),
    pytest.param(_log({**HEADER, "joints": [1, 2]}), "joints", id="header-joints-numbers"),
    pytest.param(_log({**HEADER, "joints": ["j"] * 1000}), "joints", id="header-1000-joints"),
    pytest.param(_log({k: v for k, v in HEADER.items() if k != "spec"}), "spec", id="header-no-spec"),
    pytest.param(_log({**HEADER, "spec": ["x"]}), "spec", id="header-spec-a-list"),
    pytest.param(_log({**HEADER, "rate_hz": 0}), "rate_hz", id="rate-zero"),
    pytest.param(_log({**HEADER, "rate_hz": -20}), "rate_hz", id="rate-negative"),
    pytest.param(_log({**HEADER, "rate_hz": "fast"}), "rate_hz", id="rate-a-string"),
    pytest.param(_log(HEADER).replace("20.0", "Infinity"), "rate_hz", id="rate-inf"),
    pytest.param(_log(HEADER).replace("20.0", "NaN"), "rate_hz", id="rate-nan"),
    pytest.param(_log(HEADER, HEADER), "second header", id="two-headers"),
    pytest.param(_log(HEADER, _step(target=[0.1])), "target", id="target-too-short"),
    pytest.param(_log(HEADER, _step(target=[0.1, 0.2, 0.3])), "target", id="target-too-long"),
    pytest.param(_log(HEADER, _step(target=[0.1, 1e300])), "target", id="target-huge"),
    pytest.param(_log(HEADER, _step(target=[0.1, 0.2])).replace("[0.1, 0.2], \"measured\"", "[NaN, 0.2], \"measured\""),
                 "target", id="target-nan"),
    pytest.param(_log(HEADER, _step(target=[0.1, "a"])), "target", id="target-a-string"),
    pytest.param(_log(HEADER, _step(target={"j0": 1})), "target", id="target-a-dict"),
    pytest.param(_log(HEADER, _step(target=7)), "target", id="target-a-number"),
    pytest.param(_log(HEADER, _step(measured=[0.1, "x"])), "measured", id="measured-a-string"),
    pytest.param(_log(HEADER, _step(measured=[0.1])), "measured", id="measured-too-short"),
    pytest.param(_log(HEADER, _step(), {"type": "end", "reason": ["x"]}), "reason", id="end-reason-a-list"),
    pytest.param(_log(HEADER, _step(), "{truncated"), "not a JSON line", id="truncated-last-line"),
    pytest.param(_log({**HEADER, "spec": "../../../../etc/passwd"}), ("no such", "not", "outside", "leaves"),
                 id="spec-path-outside"),
    pytest.param(_log({**HEADER, "spec": "[link=file:///x]y[/link]"}), "[link=file:///x]y[/link]",
                 id="spec-name-with-markup"),
]


@pytest.mark.parametrize("text, expect", REPLAY_CASES)
def test_replay_refuses_bad_step_logs(text: str, expect, tmp_path: Path):
    (tmp_path / "bad.jsonl").write_text(text)
    r = dgz(tmp_path, "deploy", "--replay", "bad.jsonl")
    line = assert_one_line_error(r)
    expect = (expect,) if isinstance(expect, str) else expect
    assert any(e in line for e in expect), _describe(r)
    assert "root:" not in r.text  # /etc/passwd is never echoed


@pytest.mark.parametrize("what", ["folder", "dev-zero", "missing", "fifo"])
def test_replay_refuses_non_regular_logs(what: str, tmp_path: Path):
    target = {"folder": "d", "dev-zero": "/dev/zero", "missing": "nope.jsonl", "fifo": "f.jsonl"}[what]
    if what == "folder":
        (tmp_path / "d").mkdir()
    if what == "fifo":
        os.mkfifo(tmp_path / "f.jsonl")
    r = dgz(tmp_path, "deploy", "--replay", target)
    assert_one_line_error(r, target)
    assert r.seconds < 30


HISTORY_CASES = [
    pytest.param('{"iteration": 1, "loss": NaN}\n', "'loss'", id="nan"),
    pytest.param('{"iteration": 1, "loss": Infinity}\n', "'loss'", id="inf"),
    pytest.param('{"iteration": 1, "loss": -Infinity}\n', "'loss'", id="minus-inf"),
    pytest.param('{"iteration": 1, "loss": 1e300}\n', "'loss'", id="huge"),
    pytest.param('{"iteration": 1, "loss": "low"}\n', "'loss'", id="a-string"),
    pytest.param('{"iteration": 1, "loss": [1]}\n', "'loss'", id="a-list"),
    pytest.param('{"iteration": 1, "loss": {"a": 1}}\n', "'loss'", id="a-dict"),
    pytest.param('{"loss": 1}\n', "'iteration'", id="no-iteration"),
    pytest.param('{"iteration": "1"}\n', "'iteration'", id="iteration-a-string"),
    pytest.param('{"iteration": 1.5}\n', "'iteration'", id="iteration-a-float"),
    pytest.param('{"iteration": -1}\n', "'iteration'", id="iteration-negative"),
    pytest.param('{"iteration": 1}\n{"iteration": 1}\n', "does not follow", id="iteration-repeated"),
    pytest.param('{"iteration": 2}\n{"iteration": 1}\n', "does not follow", id="iteration-backwards"),
    pytest.param("[1, 2]\n", "not a history row", id="a-list-row"),
    pytest.param('{"iteration": 1}\n{oops\n', "not a JSON line", id="truncated"),
    pytest.param('{"iteration": 1, "": 1}\n', "field", id="empty-key"),
    pytest.param('{"iteration": 1, "' + "k" * 200 + '": 1}\n', "field", id="huge-key"),
    pytest.param("[" * 100000 + "\n", "not a JSON line", id="deeply-nested"),
]


@pytest.mark.parametrize("text, expect", HISTORY_CASES)
def test_resume_history_is_schema_checked(text: str, expect: str, tmp_path: Path):
    from dgz_cli.rl.history import read_history
    from dgz_cli.spec.errors import DgzError

    (tmp_path / "history.jsonl").write_text(text)
    with pytest.raises(DgzError) as info:
        read_history(tmp_path / "history.jsonl", 10)
    msg = info.value.message
    assert "history.jsonl" in msg and expect in msg and "\n" not in msg, msg


def test_resume_history_good_rows_are_kept_up_to_the_checkpoint(tmp_path: Path):
    from dgz_cli.rl.history import read_history

    (tmp_path / "history.jsonl").write_text('{"iteration": 1, "loss": 0.5, "success_rate": null}\n'
                                            '{"iteration": 2, "loss": 0.4}\n{"iteration": 3, "loss": 0.3}\n')
    assert [r["iteration"] for r in read_history(tmp_path / "history.jsonl", 2)] == [1, 2]


@pytest.mark.parametrize("bad", ["nan-history", "garbage-checkpoint"])
def test_failed_resume_is_one_line_and_leaves_nothing_behind(bad: str, tmp_path: Path):
    import shutil

    run = tmp_path / "run"
    shutil.copytree(Path(__file__).resolve().parents[1] / "policies" / "dgz-cpu-first", run)
    if bad == "nan-history":
        (run / "history.jsonl").write_text('{"iteration": 1, "loss": NaN}\n')
    else:
        (run / "checkpoint.yaml").write_text("iteration: [\n")
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    r = dgz(tmp_path, "train", "--resume", "--out", "run", "--hands", "dgz_tri", "--objects", "sphere",
            "--repeat", "1")
    line = assert_one_line_error(r)
    assert ("history.jsonl" in line) if bad == "nan-history" else ("checkpoint" in line), _describe(r)
    after = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    assert after == before, "the failed resume changed or added files (a tb/events file?)"
    assert not (run / "tb").exists()


# --------------------------------------------------------------------------------------------
# Loaded specs: lint catches them, and every consumer refuses them on load with one line
# --------------------------------------------------------------------------------------------

def _set(path: str, value):
    """A tamper that sets ``path`` (dotted; integers index lists) to ``value``."""
    def tamper(s: dict) -> dict:
        *head, last = [int(p) if p.isdigit() else p for p in path.split(".")]
        obj = s
        for p in head:
            obj = obj[p]
        obj[int(last) if isinstance(obj, list) else last] = value
        return s
    return tamper


def _first_finger_node(s: dict) -> str:
    return next(n["id"] for n in s["nodes"] if n["parent"] is not None)


def _row_node(value):
    return _set("joints.0.node", value)


def _dup_node(s: dict) -> dict:
    s["nodes"].append(dict(s["nodes"][-1]))
    return s


def _dup_row(s: dict) -> dict:
    s["joints"].append(dict(s["joints"][0]))
    return s


def _swap_limits(s: dict) -> dict:
    r = s["joints"][0]
    r["lower"], r["upper"] = 1.0, -1.0
    return s


def _unknown_parent(s: dict) -> dict:
    s["nodes"][1]["parent"] = "no_such_node"
    return s


def _mimic_unknown_source(s: dict) -> dict:
    s["mimic"] = [dict(joint="m0", source="no_such_joint", multiplier=1.0, offset=0.0, node=None)]
    return s


def _mimic_unknown_node(s: dict) -> dict:
    s["mimic"] = [dict(joint="m0", source=s["joints"][0]["joint"], multiplier=1.0, offset=0.0, node="ghost")]
    return s


def _mask_unknown_node(s: dict) -> dict:
    s["activation_mask"]["ghost"] = [1, 0, 0]
    return s


def _mask_row(row):
    def tamper(s: dict) -> dict:
        s["activation_mask"][next(iter(s["activation_mask"]))] = row
        return s
    return tamper


def _features_unknown_node(s: dict) -> dict:
    s["features"]["values"]["ghost"] = [0.0] * 27
    return s


def _command_order(order):
    def tamper(s: dict) -> dict:
        names = [r["joint"] for r in s["joints"]]
        s["overrides"]["command_order"] = order(names)
        return s
    return tamper


def _finger_axis_equals_normal(s: dict) -> dict:
    s["palm"]["finger_axis"] = list(s["palm"]["normal"])
    return s


def _lateral_flipped(s: dict) -> dict:
    s["palm"]["lateral"] = [-x for x in s["palm"]["lateral"]]
    return s


NAN, INF = float("nan"), float("inf")
SPEC_CASES = [
    pytest.param(_set("palm.normal", [0.0, 0.0, 0.0]), "palm.normal", id="palm-normal-zero"),
    pytest.param(_set("palm.normal", [NAN, 0.0, 1.0]), "palm.normal", id="palm-normal-nan"),
    pytest.param(_set("palm.normal", [NAN, NAN, NAN]), "palm.normal", id="palm-normal-all-nan"),
    pytest.param(_set("palm.normal", [INF, 0.0, 0.0]), "palm.normal", id="palm-normal-inf"),
    pytest.param(_set("palm.normal", [0.0, 0.0, 2.0]), "unit vector", id="palm-normal-length-2"),
    pytest.param(_set("palm.normal", [0.0, 1.0]), "palm.normal", id="palm-normal-two-numbers"),
    pytest.param(_set("palm.normal", "up"), "palm.normal", id="palm-normal-a-string"),
    pytest.param(_set("palm.finger_axis", [0.0, 0.0, 0.0]), "palm.finger_axis", id="finger-axis-zero"),
    pytest.param(_set("palm.lateral", [1e-9, 0.0, 0.0]), "palm.lateral", id="lateral-tiny"),
    pytest.param(_finger_axis_equals_normal, "orthogonal", id="finger-axis-along-normal"),
    pytest.param(_lateral_flipped, "normal × finger_axis", id="lateral-flipped"),
    pytest.param(_set("palm.center", [1e9, 0.0, 0.0]), "palm.center", id="palm-center-huge"),
    pytest.param(_set("palm.center", [NAN, 0.0, 0.0]), "palm.center", id="palm-center-nan"),
    pytest.param(_set("nodes.1.anchor_point", [NAN, 0.0, 0.0]), "anchor_point", id="anchor-point-nan"),
    pytest.param(_row_node("no_such_node"), "unknown node 'no_such_node'", id="mh-row-unknown-node"),
    pytest.param(_row_node(""), "unknown node", id="mh-row-empty-node"),
    pytest.param(_set("joints.0.node", None), "joints.0.node", id="mh-row-null-node"),
    pytest.param(_unknown_parent, "unknown parent 'no_such_node'", id="node-unknown-parent"),
    pytest.param(_dup_node, "more than once", id="duplicate-node-id"),
    pytest.param(_dup_row, "more than once", id="duplicate-mh-row"),
    pytest.param(_swap_limits, "lower 1.0 > upper -1.0", id="lower-above-upper"),
    pytest.param(_set("joints.0.lower", NAN), "finite", id="lower-nan"),
    pytest.param(_set("joints.0.upper", INF), "finite", id="upper-inf"),
    pytest.param(_set("joints.0.velocity", NAN), "finite", id="velocity-nan"),
    pytest.param(_set("joints.0.primitive", "TWIST"), "primitive", id="unknown-primitive"),
    pytest.param(_set("joints.0.sign", 0), "sign", id="sign-zero"),
    pytest.param(_mimic_unknown_source, "not in M_h", id="mimic-unknown-source"),
    pytest.param(_mimic_unknown_node, "unknown node 'ghost'", id="mimic-unknown-node"),
    pytest.param(_mask_unknown_node, "unknown node 'ghost'", id="mask-unknown-node"),
    pytest.param(_mask_row([1, 2, 0]), "0/1", id="mask-row-not-bits"),
    pytest.param(_mask_row([1, 0]), "0/1", id="mask-row-two-flags"),
    pytest.param(_features_unknown_node, "unknown node 'ghost'", id="features-unknown-node"),
    pytest.param(_command_order(lambda n: n[:-1] + ["no_such_joint"]), "'no_such_joint' is not an actuated joint",
                 id="command-order-unknown-joint"),
    pytest.param(_set("nodes.1.finger", "tentacle"), "finger", id="unknown-finger-class"),
]


@pytest.mark.parametrize("tamper, expect", SPEC_CASES)
def test_lint_catches_broken_loaded_specs(tamper, expect: str, good_spec: dict, tmp_path: Path):
    test_lint_rejects_tampered_spec(tamper, expect, good_spec, tmp_path)


CONSUMER_CASES = [c for c in SPEC_CASES if c.id in ("palm-normal-zero", "palm-normal-nan", "mh-row-unknown-node",
                                                     "lower-above-upper", "mask-unknown-node")]


@pytest.mark.parametrize("tamper, expect", CONSUMER_CASES)
@pytest.mark.parametrize("command", ["show", "scene", "eval"])
def test_consumers_refuse_broken_specs_on_load(command: str, tamper, expect: str, good_spec: dict, tmp_path: Path):
    import copy

    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(tamper(copy.deepcopy(good_spec)), sort_keys=False))
    args = {"show": ("show", "bad.yaml"), "scene": ("scene", "--hand", "bad.yaml", "--object", "sphere", "-o", "s.xml"),
            "eval": ("eval", "--hand", "bad.yaml", "--objects", "sphere", "--trials", "1")}[command]
    r = dgz(tmp_path, *args)
    assert_one_line_error(r, "bad.yaml", expect)
    assert not (tmp_path / "s.xml").exists()


@pytest.mark.parametrize("reference", ["../outside/secret.urdf", "dgz://hands/../../../../../etc/passwd", "/dev/zero",
                                       "FIFO", "hands"])
def test_lint_fails_on_a_provenance_path_outside_its_root_or_not_a_file(reference: str, good_spec: dict,
                                                                         tmp_path: Path):
    import copy

    root = _make_root(tmp_path)
    if reference == "FIFO":
        reference = str(tmp_path / "fifo.urdf")
        os.mkfifo(reference)
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(_provenance(reference)(copy.deepcopy(good_spec)), sort_keys=False))
    r = dgz(tmp_path, "lint", "bad.yaml", "--asset-root", str(root))
    assert_no_traceback(r)
    assert any("provenance.urdf" in ln for ln in _lint_error_lines(r)), _describe(r)
    assert_nonzero_exit(r)


def test_lint_only_warns_when_the_urdf_is_merely_absent(good_spec: dict, tmp_path: Path):
    import copy

    root = _make_root(tmp_path)
    (tmp_path / "s.yaml").write_text(yaml.safe_dump(_provenance("hands/h/nope.urdf")(copy.deepcopy(good_spec)),
                                                    sort_keys=False))
    r = dgz(tmp_path, "lint", "s.yaml", "--asset-root", str(root))
    assert r.code == 0 and "warning" in r.stdout and "URDF not checked" in r.stdout, _describe(r)


# --------------------------------------------------------------------------------------------
# Misleading messages: name the real cause
# --------------------------------------------------------------------------------------------

def _strip_collision(text: str, links: list[str]) -> str:
    import re

    for link in links:
        text = re.sub(r'(<link name="%s">.*?)<collision>.*?</collision>' % link, r"\1", text, flags=re.S)
    return text


@pytest.mark.parametrize("links, expect", [
    (["b_prox", "b_dist"], "finger 'middle' has no collision geometry"),
    (["a_prox", "a_dist"], "has no collision geometry (links a_dist, a_prox)"),
    (["a_prox", "a_dist", "b_prox", "b_dist"], "has no collision geometry"),
    (["palm", "a_prox", "a_dist", "b_prox", "b_dist"], "the hand has no collision geometry"),
], ids=["one-finger", "other-finger", "all-fingers", "whole-hand"])
def test_onboard_names_missing_collision_geometry(links, expect: str, tmp_path: Path):
    (tmp_path / "hand.urdf").write_text(_strip_collision(GOOD, links))
    r = dgz(tmp_path, "onboard", "hand.urdf", "-o", "out.yaml")
    assert_no_traceback(r)
    errors = [ln for ln in r.stdout.splitlines() if ln.startswith("error")]
    assert any(expect in ln for ln in errors), _describe(r)
    assert not any("functional check" in ln for ln in errors), "the consequence is reported, not the cause"
    assert not (tmp_path / "out.yaml").exists()
    assert_nonzero_exit(r)


@pytest.mark.parametrize("order, expect", [
    ("[a_j1, a_j2, b_j1, b_jX]", "names 'b_jX', which is not an actuated joint"),
    ("[a_j1, a_j2, b_j1, b_j1]", "lists 'b_j1' more than once"),
    ("[a_j1, a_j2, b_j1]", "does not list 'b_j2'"),
    ("[a_j1, a_j2, b_j1, b_j2, extra]", "names 'extra'"),
], ids=["unknown", "duplicate", "missing", "extra"])
def test_onboard_names_the_bad_command_order_entry(order: str, expect: str, tmp_path: Path):
    (tmp_path / "hand.urdf").write_text(GOOD)
    (tmp_path / "ov.yaml").write_text(f"command_order: {order}\n")
    r = dgz(tmp_path, "onboard", "hand.urdf", "--overrides", "ov.yaml", "-o", "out.yaml")
    assert_one_line_error(r, "command_order", expect)
    assert not (tmp_path / "out.yaml").exists()
