"""Partitioning and excitation on dgz's own small hands (mimic, continuous joint, left hand, xacro)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from conftest import BUILTIN
from dgz_cli.onboard.pipeline import onboard
from dgz_cli.spec.io import load_spec
from dgz_cli.spec.models import Overrides

TRI, LEFT, QUAD = BUILTIN / "dgz_tri.urdf", BUILTIN / "dgz_tri_left.urdf", BUILTIN / "dgz_quad_continuous.urdf"


@pytest.fixture(scope="module")
def tri():
    return onboard(TRI, "tri").spec


def _row(spec, joint):
    return next(r for r in spec.joints if r.joint == joint)


def test_tri_structure(tri):
    assert tri.palm.link == "palm" and tri.palm.side == "right"
    assert tri.palm.normal == pytest.approx([0, 1, 0], abs=1e-6)  # the fingers curl toward +y
    assert tri.palm.finger_axis == pytest.approx([0, 0, 1], abs=1e-6)
    assert {n.finger for n in tri.nodes} == {"wrist", "thumb", "middle", "ring"}
    assert [n.id for n in tri.nodes if n.finger == "thumb"] == ["thumb_proximal", "thumb_distal", "thumb_tip"]
    # each finger: [abd, mcp] proximal, [pip] middle, [dip (mimic)] distal, then the fingertip
    by_id = {n.id: n for n in tri.nodes}
    assert by_id["middle_proximal"].joints == ["index_abd", "index_mcp"]
    assert by_id["middle_distal"].joints == ["index_dip"] and by_id["middle_distal"].parent == "middle_middle"
    tip = by_id["middle_tip"]
    assert tip.joints == [] and tip.anchor_link == "index_distal" and tip.anchor_point[2] > 0.025


def test_tri_excitation(tri):
    for j in ("index_mcp", "index_pip", "middle_mcp", "middle_pip", "thumb_mcp", "thumb_ip"):
        r = _row(tri, j)
        assert (r.primitive.value, r.sign) == ("FLEX", 1), j  # the URDF curls toward +y for positive values
    assert _row(tri, "index_abd").primitive.value == "ABD"
    assert _row(tri, "thumb_rot").primitive.value == "ROT"
    assert _row(tri, "index_mcp").margin > 0.9 and not _row(tri, "index_mcp").flagged
    # index_abd (axis +y) at x=-0.015: + moves it toward -x; it is the finger on the thumb side, which
    # dgz calls "middle" (2 non-thumb fingers = middle/ring, as for Barrett): middle's +ABD is toward the thumb.
    assert _row(tri, "index_abd").sign == -1
    assert _row(tri, "middle_abd").sign == 1  # "ring": away from the middle finger, i.e. toward +x


def test_mimic_joints_recorded_not_commanded(tri):
    mimic = {m.joint: m for m in tri.mimic}
    assert set(mimic) == {"index_dip", "middle_dip"}
    assert mimic["index_dip"].source == "index_pip" and mimic["index_dip"].multiplier == pytest.approx(0.8)
    assert "index_dip" not in {r.joint for r in tri.joints}
    assert tri.activation_mask["middle_distal"] == [0, 0, 0]  # only a mimic joint lives there


def test_left_hand_is_detected_and_mirrors_the_map(tri):
    left = onboard(LEFT, "tri_left").spec
    assert left.palm.side == "left"
    # l = n × f is the same right-handed axis for both hands; the thumb sits on −l (right) or +l (left)
    assert left.palm.lateral == pytest.approx(tri.palm.lateral, abs=1e-6)
    assert [(r.joint, r.node, r.primitive, r.sign) for r in left.joints] == \
           [(r.joint, r.node, r.primitive, r.sign) for r in tri.joints]


def test_continuous_joint_and_thumbless_hand():
    quad = onboard(QUAD, "quad").spec
    assert {n.finger for n in quad.nodes} == {"wrist", "index", "middle", "ring", "little"}
    f2 = _row(quad, "f2_abd")
    assert f2.primitive.value == "ABD" and (f2.lower, f2.upper) == pytest.approx((-3.141593, 3.141593))
    assert [n.finger for n in quad.nodes if n.id.endswith("_proximal")] == ["index", "middle", "ring", "little"]


def test_override_is_applied_and_kept_apart(tri):
    ov = Overrides.model_validate({"joints": {"thumb_rot": {"sign": 1, "reason": "test: pretend the twist is reversed"}}})
    spec = onboard(TRI, "tri", overrides=ov).spec
    row = _row(spec, "thumb_rot")
    assert (row.sign, row.source, row.identified_sign) == (1, "override", _row(tri, "thumb_rot").sign)
    assert spec.overrides.joints["thumb_rot"].reason.startswith("test")


def _dgz(*args, cwd):
    return subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", *args], cwd=cwd, capture_output=True, text=True)


def test_cli_json_summary_and_reonboard_keeps_overrides(tmp_path):
    ov = tmp_path / "ov.yaml"
    ov.write_text("joints:\n  thumb_rot:\n    sign: 1\n    reason: test override\n")
    out = tmp_path / "tri.yaml"
    res = _dgz("onboard", str(TRI), "-o", str(out), "--overrides", str(ov), "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["hand"] == "dgz_tri" and summary["lint"] == "pass" and summary["output"] == str(out)
    rows = {r["joint"]: r for r in summary["joints"]}
    assert list(rows) == [r.joint for r in load_spec(out).joints]  # command order
    assert set(rows["index_mcp"]) == {"joint", "finger", "node", "primitive", "sign", "margin", "flagged"}
    assert rows["thumb_rot"]["sign"] == 1
    res = _dgz("onboard", str(TRI), "-o", str(out), cwd=tmp_path)  # no --overrides: kept from the spec
    assert res.returncode == 0 and "kept 1 override" in res.stdout
    assert next(r for r in load_spec(out).joints if r.joint == "thumb_rot").source == "override"


def test_xacro_input_with_args(tmp_path):
    text = TRI.read_text().replace('<robot name="dgz_tri">',
                                   '<robot name="dgz_tri" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                                   '<xacro:arg name="damp" default="0.05"/>')
    assert "xacro:arg" in text
    text = text.replace('damping="0.05"', 'damping="$(arg damp)"')
    src = tmp_path / "tri.urdf.xacro"
    src.write_text(text)
    spec = onboard(src, "tri", xacro_args={"damp": "0.2"}).spec
    assert {r.damping for r in spec.joints} == {0.2}
    assert spec.provenance.xacro_args == {"damp": "0.2"}
