"""A xacro file from a stranger must never run code or read outside its hand folder (issue 10, item 1).

Every payload below is first shown to be live against xacro itself (it creates a marker file or reads a
secret), then fed to ``dgz onboard`` (and ``dgz lint`` through a spec's ``provenance.urdf``) through the
real CLI: exit != 0, one ``error:`` line naming the file and the expression, no traceback, no marker file,
no secret in the output.
"""

from __future__ import annotations

import copy
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from test_bad_inputs import GOOD, XACRO_NS, _describe, assert_no_traceback, dgz, good_urdf

MARKER = "PWNED_MARKER"
SECRET = "TOPSECRET-5f3a"

# object, object.__getattribute__ and type.__subclasses__ reached with no dunder *name* in the code
O = "python.type.mro(python.type)[1]"
GA = f"python.vars({O})['__getattribute__']"
SUBS = f"python.vars(python.type)['__subclasses__']({O})"


def _system(cmd: str) -> dict[str, str]:
    """Payload variants, each of which runs ``cmd`` through os.system in an unpatched xacro."""
    wrap = f"{GA}(c,'__name__')=='_wrap_close'"
    glob_of = f"{GA}({GA}(c,'__init__'),'__globals__')"
    return {
        # the audit's escape: comprehension + subscripts on python.vars
        "escape-comprehension": f"[{glob_of}['system']('{cmd}') for c in {SUBS} if {wrap}][0]",
        # the same without a comprehension: python.filter + lambda
        "escape-lambda": (f"python.list(python.map(lambda c: {glob_of}['system']('{cmd}'), "
                          f"python.filter(lambda c: {wrap}, {SUBS})))"),
        # a xacro module function's globals hold `os`: subscript chains, no getattr and no comprehension
        "escape-module-globals": f"python.vars({GA}(xacro.tokenize,'__globals__')['os'])['system']('{cmd}')",
        # __import__ reached through string keys only
        "escape-__import__-by-string": (f"{GA}(xacro.tokenize,'__globals__')['__builtins__']['__import__']('os')"
                                        f".system('{cmd}')"),
        # the deprecated top-level alias of xacro.tokenize
        "escape-toplevel-alias": f"python.vars({GA}(load_yaml,'__globals__')['os'])['system']('{cmd}')",
    }


def _xacro_doc(body: str) -> str:
    return good_urdf(robot_open=XACRO_NS, body_extra=body)


def _expr_link(expr: str) -> str:
    return f'  <link name="${{{expr}}}"/>\n'


def _raw_xacro(path: Path, cwd: Path) -> subprocess.CompletedProcess:
    """Expand with xacro itself (no dgz guard), to prove that a payload is live."""
    code = f"import xacro; print(xacro.process_file({str(path)!r}).toxml())"
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=60)


def _error_lines(r) -> list[str]:
    return [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]


def _assert_refused(r, tmp_path: Path, *must_name: str) -> str:
    assert_no_traceback(r)
    assert r.code != 0, _describe(r)
    lines = _error_lines(r)
    assert len(lines) == 1, "expected exactly one error line\n" + _describe(r)
    for s in must_name:
        assert s in lines[0], f"error line does not name {s!r}\n" + _describe(r)
    assert not (tmp_path / MARKER).exists(), "the payload ran: marker file created"
    assert not list(tmp_path.rglob(MARKER)), "the payload ran: marker file created"
    assert SECRET not in r.text, "a secret file's content was echoed"
    assert not (tmp_path / "out.yaml").exists()
    return lines[0]


# --------------------------------------------------------------------------------------------
# code execution
# --------------------------------------------------------------------------------------------

PAYLOADS = _system(f"touch {MARKER}")


@pytest.mark.parametrize("name", list(PAYLOADS))
def test_payload_is_live_against_raw_xacro(name, tmp_path):
    """Keeps the corpus honest: each payload really executes code in xacro without dgz's guard."""
    (tmp_path / "hand").mkdir()
    src = tmp_path / "hand" / "evil.xacro"
    src.write_text(_xacro_doc(_expr_link(PAYLOADS[name])))
    res = _raw_xacro(src, tmp_path / "hand")
    if not (tmp_path / "hand" / MARKER).exists():
        pytest.skip(f"this xacro version already refuses {name}: {res.stderr.strip()[-200:]}")


@pytest.mark.parametrize("name", list(PAYLOADS))
def test_onboard_refuses_code_execution(name, tmp_path):
    (tmp_path / "evil.xacro").write_text(_xacro_doc(_expr_link(PAYLOADS[name])))
    r = dgz(tmp_path, "onboard", "evil.xacro", "-o", "out.yaml")
    line = _assert_refused(r, tmp_path, "evil.xacro", "refused xacro expression")
    assert "python." in line or "tokenize" in line  # the expression is named


NOT_ARITHMETIC = {
    "load_yaml-namespaced": ("xacro.load_yaml('SECRETFILE')", "attribute access"),
    "load_yaml-toplevel": ("load_yaml('SECRETFILE')", "load_yaml"),
    "abs_filename": ("xacro.abs_filename('x')", "attribute access"),
    "lambda": ("(lambda: 1)()", "lambda"),
    "list-comprehension": ("[c for c in 'ab']", "comprehension"),
    "generator": ("max(c for c in [1, 2])", "comprehension"),
    "subscript-on-literal": ("'abc'[0]", "subscript"),
    "attribute-on-literal": ("'ab'.upper()", "attribute access"),
    "dunder-name": ("__import__", "__import__"),
    "python-namespace": ("python.len('ab')", "attribute access"),
    "python-builtin-type": ("type", "type"),
    "vars-toplevel": ("vars", "vars"),
    "walrus": ("(x := 1)", "assignment"),
    "f-string": ("f'ab'", "f-string"),  # (a '}' would end the ${...} expression)
    "huge-power": ("9**9**9", "exponent"),
}


@pytest.mark.parametrize("name", list(NOT_ARITHMETIC))
def test_onboard_refuses_non_arithmetic_expression(name, tmp_path):
    secret = tmp_path / "secret.yaml"
    secret.write_text(f"k: {SECRET}\n")
    expr, why = NOT_ARITHMETIC[name]
    (tmp_path / "hand").mkdir()
    (tmp_path / "hand" / "x.xacro").write_text(_xacro_doc(_expr_link(expr.replace("SECRETFILE", str(secret)))))
    r = dgz(tmp_path, "onboard", "hand/x.xacro", "-o", "out.yaml")
    _assert_refused(r, tmp_path, "x.xacro", "refused xacro", why)


def test_onboard_refuses_payload_in_an_included_file(tmp_path):
    (tmp_path / "macros.xacro").write_text(
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        f'  <xacro:macro name="evil">{_expr_link(PAYLOADS["escape-comprehension"])}</xacro:macro>\n</robot>\n')
    (tmp_path / "hand.xacro").write_text(_xacro_doc('  <xacro:include filename="macros.xacro"/>\n  <xacro:evil/>\n'))
    r = dgz(tmp_path, "onboard", "hand.xacro", "-o", "out.yaml")
    _assert_refused(r, tmp_path, "refused xacro expression")


def test_onboard_refuses_payload_in_a_property_and_an_arg(tmp_path):
    """Expressions built from properties or --xacro-arg values are checked after substitution."""
    (tmp_path / "p.xacro").write_text(_xacro_doc(
        f'  <xacro:property name="evil" value="${{{PAYLOADS["escape-module-globals"]}}}"/>\n'
        '  <link name="${evil}"/>\n'))
    r = dgz(tmp_path, "onboard", "p.xacro", "-o", "out.yaml")
    _assert_refused(r, tmp_path, "p.xacro", "refused xacro expression")
    (tmp_path / "a.xacro").write_text(_xacro_doc('  <xacro:arg name="x" default="1"/>\n'
                                                 '  <link name="${$(arg x)}"/>\n'))
    r = dgz(tmp_path, "onboard", "a.xacro", "-o", "out.yaml", "--xacro-arg",
            f"x={PAYLOADS['escape-module-globals']}")
    _assert_refused(r, tmp_path, "a.xacro", "refused xacro expression")


def test_onboard_refuses_eval_comments(tmp_path):
    (tmp_path / "c.xacro").write_text(_xacro_doc(
        f'  <!-- xacro:eval-comments -->\n  <!-- ${{{PAYLOADS["escape-module-globals"]}}} -->\n  <link name="zz"/>\n'))
    r = dgz(tmp_path, "onboard", "c.xacro", "-o", "out.yaml")
    _assert_refused(r, tmp_path, "c.xacro", "refused xacro expression")


@pytest.mark.parametrize("subst", ["$(eval 1+1)", "$(env HOME)", "$(optenv HOME x)"])
def test_onboard_refuses_eval_and_env_substitutions(subst, tmp_path):
    (tmp_path / "s.xacro").write_text(_xacro_doc(f'  <link name="{subst}"/>\n'))
    r = dgz(tmp_path, "onboard", "s.xacro", "-o", "out.yaml")
    _assert_refused(r, tmp_path, "s.xacro", "refused xacro substitution", subst.split()[0])


# --------------------------------------------------------------------------------------------
# reading outside the hand folder
# --------------------------------------------------------------------------------------------

INCLUDE_ROBOT = ('<robot xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
                 f'  <link name="{SECRET}"/>\n</robot>\n')


@pytest.mark.parametrize("how", ["dotdot", "absolute", "symlink", "find-then-dotdot", "glob"])
def test_onboard_refuses_include_outside_the_hand_folder(how, tmp_path):
    hand = tmp_path / "a" / "b" / "hand"
    hand.mkdir(parents=True)
    (tmp_path / "outside.xacro").write_text(INCLUDE_ROBOT)
    target = {
        "dotdot": "../../../outside.xacro",
        "absolute": str(tmp_path / "outside.xacro"),
        "symlink": "inside.xacro",
        "find-then-dotdot": "$(find hand)/../../../outside.xacro",
        "glob": "../../../out*.xacro",
    }[how]
    if how == "symlink":
        (hand / "inside.xacro").symlink_to(tmp_path / "outside.xacro")
    (hand / "hand.xacro").write_text(_xacro_doc(f'  <xacro:include filename="{target}"/>\n'))
    r = dgz(tmp_path, "onboard", str(hand / "hand.xacro"), "-o", "out.yaml")
    _assert_refused(r, tmp_path, "hand.xacro", "refused xacro include", "leaves the hand folder")


def test_onboard_refuses_include_of_a_device_or_entity_file(tmp_path):
    (tmp_path / "ent.xacro").write_text('<!DOCTYPE r [ <!ENTITY x "y"> ]>\n<robot/>\n')
    (tmp_path / "hand.xacro").write_text(_xacro_doc('  <xacro:include filename="ent.xacro"/>\n'))
    r = dgz(tmp_path, "onboard", "hand.xacro", "-o", "out.yaml")
    _assert_refused(r, tmp_path, "refused xacro include", "DOCTYPE")


# --------------------------------------------------------------------------------------------
# what must keep working
# --------------------------------------------------------------------------------------------

def test_ordinary_xacro_still_onboards(tmp_path):
    """Properties, math, macros with defaults, $(arg), $(find pkg) and an include inside the package."""
    pkg = tmp_path / "two_finger_description"
    (pkg / "urdf").mkdir(parents=True)
    (pkg / "urdf" / "consts.xacro").write_text(
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
        '  <xacro:property name="upper" value="${radians(90) - 0.0707963267948966}"/>\n</robot>\n')
    text = GOOD.replace('<robot name="two_finger">', XACRO_NS + '\n  <xacro:arg name="w" default="0.02"/>\n'
                        '  <xacro:include filename="$(find two_finger_description)/urdf/consts.xacro"/>\n'
                        '  <xacro:property name="half" value="${pi / 2}"/>\n')
    text = text.replace('upper="1.5"', 'upper="${upper if half > 1 else 0}"', 1)
    text = text.replace('<box size="0.02 0.02 0.04"/>', '<box size="$(arg w) 0.02 ${max(0.04, 2 * 0.01)}"/>', 1)
    (pkg / "urdf" / "hand.urdf.xacro").write_text(text)
    (tmp_path / "hand.urdf").write_text(GOOD)
    r = dgz(tmp_path, "onboard", str(pkg / "urdf" / "hand.urdf.xacro"), "-o", "x.yaml", "--name", "two_finger")
    assert r.code == 0, _describe(r)
    r2 = dgz(tmp_path, "onboard", "hand.urdf", "-o", "u.yaml", "--name", "two_finger")
    assert r2.code == 0, _describe(r2)
    a, b = yaml.safe_load((tmp_path / "x.yaml").read_text()), yaml.safe_load((tmp_path / "u.yaml").read_text())
    assert a["joints"] == b["joints"] and a["nodes"] == b["nodes"]


def test_check_xacro_expression_accepts_arithmetic():
    from dgz_cli.spec.urdfxml import check_xacro_expression

    for expr in ("1 + 2 * 3", "pi / 2", "math.pi", "sin(radians(30)) * w", "-w if flip else w", "'a' + 'b'",
                 "max(1, 2)", "x ** 2", "2 ** -0.5", "(1, 2)", "not flag and x >= 0", "math.atan2(1, 2)"):
        check_xacro_expression(expr, lambda n: n in {"w", "flip", "flag", "x"})


def test_lint_refuses_spec_whose_provenance_is_an_evil_xacro(tmp_path):
    """`dgz lint spec.yaml` reads provenance.urdf: a xacro there is checked the same way."""
    (tmp_path / "good.urdf").write_text(GOOD)
    r = dgz(tmp_path, "onboard", "good.urdf", "-o", "good.yaml")
    assert r.code == 0, _describe(r)
    spec = yaml.safe_load((tmp_path / "good.yaml").read_text())
    (tmp_path / "evil.xacro").write_text(_xacro_doc(_expr_link(PAYLOADS["escape-comprehension"])))
    bad = copy.deepcopy(spec)
    bad["provenance"]["urdf"] = str(tmp_path / "evil.xacro")
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(bad, sort_keys=False))
    r = dgz(tmp_path, "lint", "bad.yaml")
    assert_no_traceback(r)
    assert r.code != 0, _describe(r)
    assert "refused xacro expression" in r.text, _describe(r)
    assert not (tmp_path / MARKER).exists(), "the payload ran: marker file created"
