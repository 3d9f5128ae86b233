"""Issue 13: the classes of hand that onboarding got wrong or refused, as small URDFs written here.

Each fixture's expected labels follow from how it is built (which way each joint's axis turns the digit),
and each test failed on the code before issue 13: a claw whose digits point along the plate normal with
mixed axis conventions, a MANO-like thumb with diagonal axes, a parallel-jaw gripper (prismatic + mimic,
.glb visuals), a thumb whose abduction swings within the palm plane, two opposed revolute digits, and
lint's ABD check on long claw digits that cross at its half-closed pose.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dgz_cli.onboard.pipeline import onboard
from dgz_cli.onboard.verify import lint_file

INERTIA = ('<inertial><mass value="0.02"/><inertia ixx="1e-6" ixy="0" ixz="0" iyy="1e-6" iyz="0" izz="1e-6"/>'
           '</inertial>')


def _v(x) -> str:
    return " ".join(f"{float(c):.6g}" for c in x)


def _spheres(end, r=0.007) -> str:
    """Collision of a phalanx from the link origin to ``end``: spheres at its middle and its end."""
    end = np.asarray(end, float)
    return "".join(f'<collision><origin xyz="{_v(p)}"/><geometry><sphere radius="{r}"/></geometry></collision>'
                   for p in (0.5 * end, end))


class Urdf:
    def __init__(self, name: str, palm_box=(0.09, 0.08, 0.02), palm_at=(0.045, 0, 0)) -> None:
        self.parts = [f'<link name="palm">{INERTIA}<collision><origin xyz="{_v(palm_at)}"/><geometry>'
                      f'<box size="{_v(palm_box)}"/></geometry></collision></link>']
        self.name = name

    def link(self, name: str, body: str) -> None:
        self.parts.append(f'<link name="{name}">{INERTIA}{body}</link>')

    def joint(self, name, parent, child, xyz, axis, lo, hi, kind="revolute", mimic=None) -> None:
        m = f'<mimic joint="{mimic[0]}" multiplier="{mimic[1]}"/>' if mimic else ""
        self.parts.append(f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                          f'<origin xyz="{_v(xyz)}"/><axis xyz="{_v(axis)}"/>'
                          f'<limit lower="{lo}" upper="{hi}" effort="1" velocity="2"/>{m}</joint>')

    def digit(self, name: str, base, direction, lengths, axes, signs, mimic_last=False) -> None:
        """A serial digit from ``base`` along ``direction``; joint k turns about signs[k]·axes[k] and its wider
        range side is the + side when signs[k] = +1."""
        d = np.asarray(direction, float) / np.linalg.norm(direction)
        parent, origin = "palm", np.asarray(base, float)
        for k, (length, axis, s) in enumerate(zip(lengths, axes, signs)):
            child = f"{name}_l{k + 1}"
            self.link(child, _spheres(d * length))
            lo, hi = (-0.1, 1.4) if s > 0 else (-1.4, 0.1)
            mimic = (f"{name}_j{k}", 1.0 * s * signs[k - 1]) if mimic_last and k == len(lengths) - 1 and k else None
            self.joint(f"{name}_j{k + 1}", parent, child, origin, s * np.asarray(axis, float), lo, hi, mimic=mimic)
            parent, origin = child, d * length

    def write(self, folder: Path) -> Path:
        path = folder / f"{self.name}.urdf"
        path.write_text(f'<?xml version="1.0"?>\n<robot name="{self.name}">\n' + "\n".join(self.parts) + "\n</robot>\n")
        return path


def _labels(spec) -> dict[str, tuple[str, int]]:
    return {r.joint: (r.primitive.value, r.sign) for r in spec.joints}


def _lint_errors(result, folder: Path) -> list[str]:
    return [f.message for f in lint_file(result.spec, folder / "spec.yaml", None, result.poser) if f.level == "error"]


def _flat_fingers(u: Urdf, n: int = 3, lengths=(0.045, 0.035), x0: float = 0.09, y0: float = -0.025,
                  dy: float = 0.025) -> None:
    """n fingers along +x from the palm's edge x0, curling toward +z (axis −y), index nearest −y."""
    for i in range(n):
        u.digit(f"f{i + 1}", (x0, y0 + i * dy, 0), (1, 0, 0), lengths, [(0, -1, 0)] * len(lengths), [1] * len(lengths))


# ---- 1. radially symmetric claw, digits along the palm normal, mixed axis conventions --------------------------

CLAW_SIGNS = {"a": (1, -1), "b": (-1, -1), "c": (1, 1)}


def _claw(folder: Path, lengths=(0.06, 0.05)) -> Path:
    u = Urdf("claw3", palm_box=(0.08, 0.08, 0.02), palm_at=(0, 0, -0.01))
    for name, phi in zip(CLAW_SIGNS, (90, 210, 330)):
        e = np.array([math.cos(math.radians(phi)), math.sin(math.radians(phi)), 0.0])
        close_axis = np.array([e[1], -e[0], 0.0])  # rotation about it moves a tip above the base toward −e
        u.digit(name, 0.03 * e, (0, 0, 1), lengths, [close_axis] * 2, CLAW_SIGNS[name])
    return u.write(folder)


def test_claw_digits_along_the_normal_close_toward_the_axis_each_by_its_own_excitation(tmp_path):
    result = onboard(_claw(tmp_path), "claw3")
    labels = _labels(result.spec)
    for name, signs in CLAW_SIGNS.items():
        for k, s in enumerate(signs):
            assert labels[f"{name}_j{k + 1}"] == ("FLEX", s), (name, k, labels)
    assert np.allclose(np.asarray(result.spec.palm.finger_axis) @ [0, 0, 1], 1.0, atol=0.05)  # f = the claw's axis
    assert _lint_errors(result, tmp_path) == []


# ---- 2. MANO-like thumb with diagonal MCP/IP axes -------------------------------------------------------------

def _mano(folder: Path) -> Path:
    u = Urdf("mano_like")
    _flat_fingers(u)
    d = np.array([math.cos(math.radians(50)), -math.sin(math.radians(50)), 0.0])
    curl = np.array([0.0, 0.835, 0.55])  # toward the palm side and across the palm: a diagonal curl
    curl = curl - (curl @ d) * d
    axis = np.cross(d, curl / np.linalg.norm(curl))  # +rotation moves the thumb tip along the curl: +FLEX
    u.digit("thumb", (0.03, -0.045, 0), d, (0.04, 0.03), [axis, axis], [1, 1])
    return u.write(folder)


def test_mano_like_thumb_is_judged_by_its_own_curl_axis(tmp_path):
    result = onboard(_mano(tmp_path), "mano")
    labels = _labels(result.spec)
    assert labels["thumb_j1"] == ("FLEX", 1) and labels["thumb_j2"] == ("FLEX", 1), labels
    fingers = {r.joint: next(n.finger for n in result.spec.nodes if n.id == r.node) for r in result.spec.joints}
    assert fingers["thumb_j1"] == "thumb" and fingers["f1_j1"] == "index" and result.spec.palm.side == "right"
    assert _lint_errors(result, tmp_path) == []


# ---- 3. parallel-jaw gripper: one prismatic joint + a prismatic mimic, .glb visuals only ----------------------

@pytest.mark.parametrize("axis_x,limits,sign", [(-1, (0.0, 0.02), 1), (1, (-0.005, 0.02), -1)],
                         ids=["plus-closes", "plus-opens-wider-side"])
def test_parallel_jaw_flex_closes_the_jaw(tmp_path, axis_x, limits, sign):
    (tmp_path / "jaw.glb").write_bytes(b"glTF\x02\x00\x00\x00\x0c\x00\x00\x00")
    u = Urdf("jaw", palm_box=(0.1, 0.03, 0.02), palm_at=(0, 0, 0))
    visual = '<visual><geometry><mesh filename="jaw.glb"/></geometry></visual>'
    box = '<collision><origin xyz="0 0 0.025"/><geometry><box size="0.01 0.02 0.05"/></geometry></collision>'
    for name in ("left", "right"):
        u.link(f"{name}_jaw", visual + box)
    u.joint("jaw", "palm", "left_jaw", (0.03, 0, 0.01), (axis_x, 0, 0), *limits, kind="prismatic")
    # the other jaw is mirrored (its axis points the other way) and follows with multiplier 1: the jaws close
    # together, and their axes cancel out (the palm frame was undefined before issue 13)
    u.joint("jaw_mimic", "palm", "right_jaw", (-0.03, 0, 0.01), (-axis_x, 0, 0), *limits, kind="prismatic",
            mimic=("jaw", 1))
    result = onboard(u.write(tmp_path), "jaw")
    assert _labels(result.spec) == {"jaw": ("FLEX", sign)}
    assert [m.joint for m in result.spec.mimic] == ["jaw_mimic"]
    assert np.asarray(result.spec.palm.finger_axis) @ [0, 0, 1] > 0.99  # the jaws' approach direction
    assert _lint_errors(result, tmp_path) == []


# ---- 4. thumb abduction swinging within the palm plane ---------------------------------------------------------

def test_thumb_abduction_opens_away_from_the_index_finger(tmp_path):
    """A thumb beside the palm pointing sideways, its tip level with the index tip: the gap to the index tip
    does not change under the swing, and the swing leans slightly toward −n. +ABD must still be the direction
    that opens the thumb-finger angle (tip toward the wrist), not the one that happens to go toward +n."""
    u = Urdf("side_thumb", palm_box=(0.12, 0.08, 0.02), palm_at=(0.06, 0, 0))
    _flat_fingers(u, 3, lengths=(0.03,), x0=0.12)
    swing = np.array([0.2, 0.0, -1.0]) / math.hypot(0.2, 1.0)  # +q: tip toward −x (away from the fingers), a bit −z
    u.link("thumb_base", "")
    u.joint("thumb_abd", "palm", "thumb_base", (0.145, -0.045, 0), swing, -0.5, 0.5)
    u.link("thumb_l1", _spheres((0, -0.07, 0)))
    u.joint("thumb_ip", "thumb_base", "thumb_l1", (0, 0, 0), (-1, 0, 0), -0.1, 1.4)  # curls toward +z
    result = onboard(u.write(tmp_path), "side_thumb")
    labels = _labels(result.spec)
    assert labels["thumb_abd"] == ("ABD", 1), labels
    assert labels["thumb_ip"] == ("FLEX", 1), labels
    thumb = {n.finger for n in result.spec.nodes if "thumb_abd" in n.joints or "thumb_ip" in n.joints}
    assert thumb == {"thumb"}  # found by where it points (it curls like the fingers)
    assert _lint_errors(result, tmp_path) == []


# ---- 5. two opposed revolute digits (no thumb: they tie) -------------------------------------------------------

def test_two_opposed_digits_flex_not_abd(tmp_path):
    u = Urdf("pinch", palm_box=(0.1, 0.03, 0.02), palm_at=(0, 0, -0.01))
    u.digit("left", (0.03, 0, 0), (0, 0, 1), (0.05, 0.04), [(0, -1, 0)] * 2, [1, -1])  # (0,−1,0) turns +z toward −x
    u.digit("right", (-0.03, 0, 0), (0, 0, 1), (0.05, 0.04), [(0, 1, 0)] * 2, [-1, 1])
    result = onboard(u.write(tmp_path), "pinch")
    assert _labels(result.spec) == {"left_j1": ("FLEX", 1), "left_j2": ("FLEX", -1),
                                    "right_j1": ("FLEX", -1), "right_j2": ("FLEX", 1)}
    palm = result.spec.palm
    n, f = np.asarray(palm.normal), np.asarray(palm.finger_axis)
    assert abs(np.linalg.norm(n) - 1) < 1e-3 and abs(n @ f) < 1e-3 and f @ [0, 0, 1] > 0.99
    assert _lint_errors(result, tmp_path) == []


# ---- 6. lint's ABD check on long claw digits ------------------------------------------------------------------

def test_lint_abd_check_does_not_refuse_long_claw_digits(tmp_path):
    """Three long digits 120° apart with a root twist each (a spread once the digit bends): at lint's
    half-closed pose the fingertips have crossed each other's line, which must not turn a correct spread into
    a refusal."""
    u = Urdf("claw_spread", palm_box=(0.06, 0.06, 0.02), palm_at=(0, 0, -0.01))
    for name, phi in zip(("a", "b", "c"), (90, 210, 330)):
        e = np.array([math.cos(math.radians(phi)), math.sin(math.radians(phi)), 0.0])
        close_axis = np.array([e[1], -e[0], 0.0])
        u.link(f"{name}_root", "")
        u.joint(f"{name}_spread", "palm", f"{name}_root", 0.02 * e, (0, 0, 1), -0.4, 0.4)
        parent, pos = f"{name}_root", np.zeros(3)
        for k, length in enumerate((0.09, 0.08)):
            child = f"{name}_l{k + 1}"
            u.link(child, _spheres((0, 0, length)))
            u.joint(f"{name}_j{k + 1}", parent, child, pos, close_axis, -0.1, 1.4)
            parent, pos = child, np.array([0, 0, length])
    result = onboard(u.write(tmp_path), "claw_spread")
    labels = _labels(result.spec)
    assert all(labels[f"{d}_j{k}"] == ("FLEX", 1) for d in "abc" for k in (1, 2)), labels
    assert all(labels[f"{d}_spread"][0] == "ABD" for d in "abc"), labels
    assert _lint_errors(result, tmp_path) == []


# ---- the thumb rule itself --------------------------------------------------------------------------------------

def _rot_z(deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([c, s, 0.0])


def test_thumb_rule_clear_none_radial_and_ambiguous():
    from dgz_cli.onboard.frame import ThumbAmbiguous, find_thumb

    up = np.array([0.0, 0.0, 1.0])
    fingers = [_rot_z(0)] * 3
    # a thumb pointing 40° off the fingers (curling like them) is found by its direction
    thumb, margin = find_thumb(np.array([up] * 4), np.array(fingers + [_rot_z(-40)]))
    assert thumb == 3 and margin > 0.1
    # four parallel fingers: no thumb
    assert find_thumb(np.array([up] * 4), np.array([_rot_z(0)] * 4))[0] is None
    # a claw (curls toward each other, same direction): no thumb, even with one digit slightly off
    curls = np.array([-_rot_z(a) for a in (0, 120, 240)])
    assert find_thumb(curls, np.array([up, up, [0.0, 0.2, 0.98]]))[0] is None
    # two thumb-like digits that stand out almost equally: refused by name, not guessed
    dirs = np.array([_rot_z(0), _rot_z(0), _rot_z(0), _rot_z(-30), _rot_z(32)])
    with pytest.raises(ThumbAmbiguous):
        find_thumb(np.array([up] * 5), dirs)
