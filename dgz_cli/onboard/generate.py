"""Procedural hands with ground-truth labels known by construction (`dgz hands generate`).

Every hand is built in a canonical hand frame H (x = F, the finger direction; y = L = N × F; z = N, the
palm normal, the side the fingers close toward) and hung below a root link ``base`` by a fixed joint
with a random rotation, so the palm normal may point along any world axis. The labels of every actuated
joint (finger, finger class, node, primitive, sign) follow from how the joint was built — which way its
axis points relative to the direction the hand closes, spreads or opposes — and never from running the
onboarding. The conventions are those of design.md:

- FLEX: +q moves the digit toward the palm side (+N) for fingers along F; toward the grasp axis for the
  digits of claws, opposed-digit grippers and parallel jaws (prismatic: +q closes the jaw);
- ABD (fingers, axis ±N): +q moves the digit away from the middle finger (the middle finger: toward the
  thumb, or toward +L on a hand without thumb);
- ABD (thumb, axis ± its curl direction): +q opens the thumb away from the index finger (the angle between
  the thumb and the fingers grows);
- ROT (thumb, axis ± its own long axis): +q turns the thumb pad toward the fingers (opposition).

Kinds: ``hand`` (thumb, possibly missing, plus 2–4 fingers along F), ``claw`` (3–4 digits around the palm
normal, pointing along it), ``opposed`` (two opposed revolute digits) and ``jaw`` (a prismatic joint and a
prismatic mimic). Every joint's axis convention is drawn per joint (mirrored or not); the closing side of
each range is the wider one, as on real hands.
"""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path
from typing import Literal, Optional

import numpy as np
from pydantic import BaseModel, ConfigDict

from dgz_cli.spec.io import atomic_write, atomic_write_bytes

KINDS = ("hand", "claw", "opposed", "jaw")
CLASS_NAMES = {1: ["middle"], 2: ["middle", "ring"], 3: ["index", "middle", "ring"],
               4: ["index", "middle", "ring", "little"]}
TYPES_BY_COUNT = {1: ["proximal"], 2: ["proximal", "distal"], 3: ["proximal", "middle", "distal"],
                  4: ["metacarpal", "proximal", "middle", "distal"]}
MESH_FILE = "unit_box.stl"


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class JointLabel(_Frozen):
    """Ground truth of one actuated joint."""

    joint: str
    finger: str  # the chain's name in the URDF (f0, f1, ...)
    finger_class: Optional[str]  # thumb/index/middle/ring/little; None where the hand has no canonical naming
    node: int  # index of the joint's node along its finger (0 = nearest the palm)
    node_type: str  # proximal, middle, distal, metacarpal
    primitive: Literal["FLEX", "ABD", "ROT"]
    sign: Literal[1, -1]


class HandLabels(_Frozen):
    name: str
    seed: int
    kind: str
    side: Optional[str]  # right/left for a hand with a thumb, None otherwise
    joints: tuple[JointLabel, ...]
    mimic: tuple[str, ...]  # mimic joints (not commanded, no label)
    palm_normal: Optional[tuple[float, float, float]]  # world frame; None where the naming is a free choice
    finger_axis: tuple[float, float, float]  # world frame


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _rpy_of(rot: np.ndarray) -> tuple[float, float, float]:
    """URDF rpy (R = Rz(y)·Ry(p)·Rx(r)) of a rotation matrix."""
    p = math.asin(-max(-1.0, min(1.0, rot[2, 0])))
    if abs(math.cos(p)) > 1e-6:
        r = math.atan2(rot[2, 1], rot[2, 2])
        y = math.atan2(rot[1, 0], rot[0, 0])
    else:  # gimbal lock: put everything in yaw
        r, y = 0.0, math.atan2(-rot[0, 1], rot[1, 1])
    return r, p, y


def _frame_to(z_axis: np.ndarray, x_hint: np.ndarray) -> np.ndarray:
    """Rotation whose z column is ``z_axis`` and x column is ``x_hint`` made orthogonal to it."""
    z = _unit(z_axis)
    x = x_hint - (x_hint @ z) * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0, 0]) if abs(z[0]) < 0.9 else np.array([0, 1.0, 0])
        x = x - (x @ z) * z
    x = _unit(x)
    return np.column_stack([x, np.cross(z, x), z])


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _f(x: float) -> str:
    return f"{x:.6g}" if abs(x) > 1e-12 else "0"


def _v(v) -> str:
    return " ".join(_f(float(x)) for x in v)


class _Builder:
    """Accumulates links and joints. Every link frame is parallel to the palm frame H (joint rpy = 0), so
    joint axes, origins and geometry can be written directly in H coordinates."""

    def __init__(self, rng: np.random.Generator, name: str) -> None:
        self.rng, self.name = rng, name
        self.links: list[str] = []
        self.joints: list[str] = []
        self.pos: dict[str, np.ndarray] = {}  # link origin in H at the zero pose

    def link(self, name: str, geoms: list[str], mass: float = 0.02, visuals: tuple[str, ...] = ()) -> None:
        i = mass * 2e-5 + 1e-7
        body = "".join(f"<visual>{g}</visual>" for g in visuals) + "".join(f"<collision>{g}</collision>" for g in geoms)
        self.links.append(f'<link name="{name}"><inertial><origin xyz="0 0 0" rpy="0 0 0"/><mass value="{_f(mass)}"/>'
                          f'<inertia ixx="{_f(i)}" ixy="0" ixz="0" iyy="{_f(i)}" iyz="0" izz="{_f(i)}"/></inertial>'
                          f'{body}</link>')

    def joint(self, name: str, kind: str, parent: str, child: str, origin: np.ndarray, axis=None,
              limits: tuple[float, float] | None = None, mimic: tuple[str, float] | None = None,
              rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        s = (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
             f'<origin xyz="{_v(origin)}" rpy="{_v(rpy)}"/>')
        if axis is not None:
            s += f'<axis xyz="{_v(axis)}"/>'
        if limits is not None:
            s += f'<limit lower="{_f(limits[0])}" upper="{_f(limits[1])}" effort="2" velocity="3"/>'
            s += '<dynamics damping="0.05"/>'
        if mimic is not None:
            s += f'<mimic joint="{mimic[0]}" multiplier="{_f(mimic[1])}" offset="0"/>'
        self.joints.append(s + "</joint>")

    def segment(self, start: np.ndarray, end: np.ndarray, radius: float, style: str) -> str:
        """Collision geometry (in the link frame, the link's origin at ``start``) spanning start → end."""
        d = end - start
        length = float(np.linalg.norm(d))
        rot = _frame_to(d, np.array([1.0, 0.3, 0.1]))
        mid = 0.5 * d
        rpy = _v(_rpy_of(rot))
        if style == "capsule":
            geom = f'<cylinder radius="{_f(radius)}" length="{_f(max(length - 2 * radius, 1e-3))}"/>'
            # URDF has no capsule: a cylinder plus a sphere at its far end (MuJoCo primitives)
            tip = f'<origin xyz="{_v(d - _unit(d) * radius)}" rpy="0 0 0"/><geometry><sphere radius="{_f(radius)}"/></geometry>'
            return (f'<origin xyz="{_v(mid - _unit(d) * radius * 0.5)}" rpy="{rpy}"/><geometry>{geom}</geometry>'
                    f"</collision><collision>{tip}")
        size = f"{_f(2 * radius)} {_f(2 * radius)} {_f(length)}"
        if style == "mesh":
            return f'<origin xyz="{_v(mid)}" rpy="{rpy}"/><geometry><mesh filename="meshes/{MESH_FILE}" scale="{size}"/></geometry>'
        return f'<origin xyz="{_v(mid)}" rpy="{rpy}"/><geometry><box size="{size}"/></geometry>'

    def style(self) -> str:
        return str(self.rng.choice(["capsule", "box", "mesh"]))

    def urdf(self, comment: str) -> str:
        return (f'<?xml version="1.0"?>\n<!-- {comment} -->\n<robot name="{self.name}">\n  '
                + "\n  ".join(self.links + self.joints) + "\n</robot>\n")


def _closing_range(sign: int, rng: np.random.Generator, span: float = 1.5) -> tuple[float, float]:
    """A joint range whose wider side is the closing one (+q closes when sign = +1)."""
    lo, hi = -float(rng.uniform(0.05, 0.25)), float(rng.uniform(1.0, span))
    return (lo, hi) if sign > 0 else (-hi, -lo)


def _finger_chain(b: _Builder, rng, fname: str, base: np.ndarray, direction: np.ndarray, close_dir: np.ndarray,
                  lengths: list[float], flex_signs: list[int], abd: tuple[np.ndarray, int] | None,
                  mimic_last: bool, radius: float, labels: list[dict], cls: Optional[str],
                  rot: tuple[np.ndarray, int] | None = None) -> None:
    """One digit along ``direction`` from ``base`` (H coords), flexing toward ``close_dir``.

    flex_signs[k] = +1: the k-th flexion joint's + direction closes. ``abd`` = (geometric +direction axis,
    label sign) of a root abduction joint, ``rot`` = (axis, sign) of a root twist (thumbs)."""
    d = _unit(direction)
    flex_axis = _unit(np.cross(d, close_dir))  # rotation about it moves the tip toward close_dir
    parent, parent_pos = "palm", np.zeros(3)
    pos = base.copy()
    root_joints: list[tuple[str, np.ndarray, str, int]] = []  # (name, axis, primitive, sign) at the base
    if rot is not None:
        root_joints.append((f"{fname}_rot", rot[0], "ROT", rot[1]))
    if abd is not None:
        root_joints.append((f"{fname}_abd", abd[0], "ABD", abd[1]))
    order = list(rng.permutation(len(root_joints))) if len(root_joints) > 1 else list(range(len(root_joints)))
    root_rows = []
    for k in order:
        jname, axis, prim, sign = root_joints[k]
        child = f"{jname}_link"
        b.link(child, [], mass=0.005)
        b.joint(jname, "revolute", parent, child, pos - parent_pos, axis,
                (-0.5, 0.5) if prim == "ABD" else _closing_range(1, rng, 1.2))
        parent, parent_pos = child, pos.copy()
        root_rows.append(dict(joint=jname, finger=fname, finger_class=cls, node=0, primitive=prim, sign=sign))
    n_flex = len(flex_signs)
    types = TYPES_BY_COUNT[n_flex]
    for k, (length, s) in enumerate(zip(lengths, flex_signs)):
        jname, child = f"{fname}_j{k + 1}", f"{fname}_p{k + 1}"
        end = d * length
        b.link(child, [b.segment(np.zeros(3), end, radius * (0.85 ** k), b.style())])
        axis = s * flex_axis
        limits = _closing_range(s, rng)
        is_mimic = mimic_last and k == n_flex - 1 and k > 0
        mimic = None
        if is_mimic:
            prev_sign = flex_signs[k - 1]
            mimic = (f"{fname}_j{k}", float(rng.uniform(0.6, 1.0)) * s * prev_sign)
        b.joint(jname, "revolute", parent, child, pos - parent_pos, axis, limits, mimic)
        if not is_mimic:
            labels.append(dict(joint=jname, finger=fname, finger_class=cls, node=k, node_type=types[k],
                               primitive="FLEX", sign=s))
        parent, parent_pos = child, pos.copy()
        pos = pos + end
    for r in root_rows:
        labels.append(dict(r, node_type=types[0]))


def _hand(b: _Builder, rng) -> tuple[str, Optional[str], list[dict], list[str], Optional[np.ndarray]]:
    n_fingers = int(rng.integers(2, 5))  # non-thumb fingers
    has_thumb = rng.random() < 0.8
    side = str(rng.choice(["right", "left"])) if has_thumb else None
    ts = -1.0 if side != "left" else 1.0  # thumb side along L
    F, L, N = np.eye(3)
    scale = float(rng.uniform(0.7, 1.4))
    spacing = 0.024 * scale
    width = spacing * n_fingers + 0.01
    plen = float(rng.uniform(0.07, 0.11)) * scale
    b.link("palm", [f'<origin xyz="{_v([plen / 2, 0, 0])}" rpy="0 0 0"/><geometry><box size="{_v([plen, width, 0.02 * scale])}"/></geometry>'],
           mass=0.3)
    labels: list[dict] = []
    ys = [(-(n_fingers - 1) / 2 + i) * spacing for i in range(n_fingers)]
    if has_thumb and ts > 0:
        ys = ys[::-1]  # index nearest the thumb
    classes = CLASS_NAMES[n_fingers]
    y_mid = ys[classes.index("middle")]
    for i, (y, cls) in enumerate(zip(ys, classes)):
        n_flex = int(rng.integers(1, 4))
        has_abd = rng.random() < 0.6
        lengths = [float(x * rng.uniform(0.5, 2.0) * scale) for x in (0.045, 0.03, 0.025)[:n_flex]]
        signs = [int(rng.choice([1, -1])) for _ in range(n_flex)]
        abd = None
        if has_abd:
            away = (ts if has_thumb else 1.0) if cls == "middle" else float(np.sign(y - y_mid))
            a_sign = int(rng.choice([1, -1]))  # rotation about +N moves the tip toward +L
            abd = (a_sign * N, int(a_sign * away))
        base = np.array([plen + float(rng.uniform(-0.005, 0.005)), y, 0.0])
        _finger_chain(b, rng, f"f{i + 1}", base, F, N, lengths, signs, abd, n_flex >= 2 and rng.random() < 0.3,
                      0.008 * scale, labels, cls)
    if has_thumb:
        theta = math.radians(float(rng.uniform(25, 85)))
        tilt = math.radians(float(rng.uniform(0, 15)))
        d = _unit(math.cos(theta) * F + math.sin(theta) * ts * L + math.sin(tilt) * N)
        beta = math.radians(float(rng.uniform(0, 45)))  # diagonal curl (MANO-like when large)
        u = math.cos(beta) * N - math.sin(beta) * ts * L
        u = _unit(u - (u @ d) * d)
        n_flex = int(rng.integers(1, 3))
        has_rot, has_abd = rng.random() < 0.5, rng.random() < 0.6
        while n_flex + has_rot + has_abd > 4:
            has_rot = False
        fperp = _unit(F - (F @ d) * d)
        rot = abd = None
        if has_abd:
            b_sign = int(rng.choice([1, -1]))
            swing = np.cross(u, d)  # tip motion of +rotation about +u
            opens = -1 if swing @ fperp > 0 else 1  # the thumb-to-fingers angle grows when swing leaves F
            abd = (b_sign * u, b_sign * opens)
        lengths = [float(x * rng.uniform(0.6, 1.8) * scale) for x in (0.04, 0.03)[:n_flex]]
        signs = [int(rng.choice([1, -1])) for _ in range(n_flex)]
        base = np.array([plen * float(rng.uniform(0.2, 0.7)), ts * width / 2, 0.0])
        if has_rot:
            r_sign = int(rng.choice([1, -1]))
            # +rotation about +d turns the pad normal u by d × u; opposition = the pad turns toward the fingers
            pad_turn = np.cross(d, u)
            toward = np.array([plen + 0.02 * scale, ys[0], 0.0]) - (base + d * sum(lengths))
            toward = _unit(toward - (toward @ d) * d)
            if abs(pad_turn @ toward) < 0.3:
                has_rot = False
            else:
                rot = (r_sign * d, r_sign * (1 if pad_turn @ toward > 0 else -1))
        _finger_chain(b, rng, "f0", base, d, u, lengths, signs, abd, False, 0.009 * scale, labels, "thumb",
                      rot=rot if has_rot else None)
    normal = N
    return "hand", side, labels, [], normal


def _radial(b: _Builder, rng, kind: str) -> tuple[str, Optional[str], list[dict], list[str], Optional[np.ndarray]]:
    """Digits on a circle around the palm normal N, pointing along N, closing toward the axis."""
    n = {"claw": int(rng.integers(3, 5)), "opposed": 2, "jaw": 2}[kind]
    scale = float(rng.uniform(0.7, 1.4))
    radius = float(rng.uniform(0.025, 0.045)) * scale
    b.link("palm", [f'<origin xyz="0 0 {_f(-0.01 * scale)}" rpy="0 0 0"/><geometry><box size="{_v([2.4 * radius, 2.4 * radius, 0.02 * scale])}"/></geometry>'],
           mass=0.3)
    phase = float(rng.uniform(0, 2 * math.pi))
    labels: list[dict] = []
    mimic: list[str] = []
    long_fingers = rng.random() < 0.4
    for i in range(n):
        phi = phase + 2 * math.pi * i / n
        e = np.array([math.cos(phi), math.sin(phi), 0.0])
        base = radius * e
        if kind == "jaw":
            b_name = f"f{i + 1}"
            child = f"{b_name}_p1"
            ext = np.array([0, 0, 0.05 * scale])
            b.link(child, [b.segment(np.zeros(3), ext, 0.008 * scale, str(rng.choice(["box", "capsule"])))],
                   visuals=('<origin xyz="0 0 0" rpy="0 0 0"/><geometry><mesh filename="meshes/jaw.glb"/></geometry>',))
            s = int(rng.choice([1, -1]))
            axis = s * (-e)  # +q along axis closes when s = +1
            travel = round(min(0.04, 0.8 * radius), 4)  # the jaws stop before they meet
            if i == 0:
                src_sign = s
                limits = (0.0, travel) if s > 0 else (-travel, 0.0)
                b.joint(f"{b_name}_j1", "prismatic", "palm", child, base, axis, limits)
                labels.append(dict(joint=f"{b_name}_j1", finger=b_name, finger_class=None, node=0,
                                   node_type="proximal", primitive="FLEX", sign=s))
            else:
                mult = float(s * src_sign)  # closes together with the source
                b.joint(f"{b_name}_j1", "prismatic", "palm", child, base, axis, (-travel, travel), ("f1_j1", mult))
                mimic.append(f"{b_name}_j1")
            continue
        n_flex = int(rng.integers(1, 4))
        base_len = (0.06, 0.045, 0.035) if long_fingers else (0.04, 0.03, 0.025)
        lengths = [float(x * rng.uniform(0.5, 2.0) * scale) for x in base_len[:n_flex]]
        signs = [int(rng.choice([1, -1])) for _ in range(n_flex)]
        _finger_chain(b, rng, f"f{i + 1}", base, np.array([0, 0, 1.0]), -e, lengths, signs, None,
                      n_flex >= 2 and rng.random() < 0.3, 0.008 * scale, labels, None)
    return kind, None, labels, mimic, None


def generate_one(seed: int, index: int, kinds: tuple[str, ...] = KINDS) -> tuple[str, HandLabels, bool]:
    """(URDF text, labels, uses the unit-box mesh) of hand ``index`` of ``seed`` (deterministic)."""
    rng = np.random.default_rng([seed, index])
    name = f"gen_{seed}_{index:04d}"
    b = _Builder(rng, name)
    weights = {"hand": 0.55, "claw": 0.2, "opposed": 0.12, "jaw": 0.13}
    p = np.array([weights[k] for k in kinds])
    kind = str(rng.choice(list(kinds), p=p / p.sum()))
    if kind == "hand":
        kind, side, labels, mimic, normal = _hand(b, rng)
        finger_axis = np.array([1.0, 0, 0])
    else:
        kind, side, labels, mimic, normal = _radial(b, rng, kind)
        finger_axis = np.array([0, 0, 1.0])
    rot = _random_rotation(rng)
    b.links.insert(0, '<link name="base"/>')
    b.joint("base_to_palm", "fixed", "base", "palm", rng.uniform(-0.1, 0.1, 3), rpy=_rpy_of(rot))
    b.joints.insert(0, b.joints.pop())
    mimic += [j for j in (s.split('"')[1] for s in b.joints if "<mimic" in s) if j not in mimic]
    text = b.urdf(f"generated by dgz hands generate, seed {seed}, hand {index}, kind {kind}; labels in "
                  f"{name}.labels.json")
    labels_model = HandLabels(
        name=name, seed=seed, kind=kind, side=side, mimic=tuple(mimic),
        joints=tuple(JointLabel(**r) for r in sorted(labels, key=lambda r: (r["finger"], r["joint"]))),
        palm_normal=None if normal is None else tuple(round(float(x), 6) for x in rot @ normal),
        finger_axis=tuple(round(float(x), 6) for x in rot @ finger_axis))
    return text, labels_model, "meshes/" + MESH_FILE in text


def _unit_box_stl() -> bytes:
    """Binary STL of the unit cube centred at the origin."""
    v = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1), (2, 3, 7), (2, 7, 6),
             (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    out = bytearray(b"dgz unit box".ljust(80, b" ") + struct.pack("<I", len(faces)))
    for f in faces:
        a, b_, c = v[list(f)]
        nrm = np.cross(b_ - a, c - a)
        nrm = nrm / np.linalg.norm(nrm)
        out += struct.pack("<12fH", *nrm, *a, *b_, *c, 0)
    return bytes(out)


def _empty_glb() -> bytes:
    """A minimal valid glTF 2.0 binary (the jaws' visual: MuJoCo never reads it, visuals are dropped)."""
    body = b'{"asset":{"version":"2.0"}}  '
    return b"glTF" + struct.pack("<II", 2, 12 + 8 + len(body)) + struct.pack("<I", len(body)) + b"JSON" + body


def write_hands(out_dir: Path, seed: int, count: int, kinds: tuple[str, ...] = KINDS) -> list[tuple[Path, Path]]:
    """Write ``count`` hands (URDF + labels JSON) into ``out_dir``; return their (urdf, labels) paths."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "meshes").mkdir(exist_ok=True)
    atomic_write_bytes(out_dir / "meshes" / MESH_FILE, _unit_box_stl())
    atomic_write_bytes(out_dir / "meshes" / "jaw.glb", _empty_glb())
    paths = []
    for i in range(count):
        text, labels, _ = generate_one(seed, i, kinds)
        urdf, lab = out_dir / f"{labels.name}.urdf", out_dir / f"{labels.name}.labels.json"
        atomic_write(urdf, text)
        atomic_write(lab, json.dumps(labels.model_dump(), indent=1) + "\n")
        paths.append((urdf, lab))
    return paths


def load_labels(path: Path) -> HandLabels:
    return HandLabels.model_validate_json(path.read_text(encoding="utf-8"))


__all__ = ["HandLabels", "JointLabel", "generate_one", "write_hands", "load_labels", "KINDS"]
