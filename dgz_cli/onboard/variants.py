"""Variants of one hand for training diversity (`dgz hands generate --variants-of HAND`), as GET-Zero did with
633 LEAP variants: each variant scales every finger's links by its own factor and may remove a fingertip joint
or a whole finger of the base hand.

The base is a reviewed spec and its URDF. The labels of a variant (finger, node, primitive, sign of every
actuated joint) follow from the base spec and from what the construction did, never from running the
onboarding:

- scaling a finger about each of its link frames (joint origins, collision/visual geometry, inertia) moves no
  joint axis, so every primitive and sign is the base's;
- removing a fingertip joint (turned into a fixed joint, its link kept) removes the finger's last node; the
  remaining nodes of that finger are typed from the tip inwards by their count (design.md: distal, middle,
  proximal, metacarpal; one node: proximal);
- removing a finger removes its subtree; it is only done where the other fingers keep their class (the finger
  farthest from the thumb of a hand with four fingers and a thumb), so finger +ABD "away from the middle
  finger" names the same direction as on the base.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from lxml import etree

from dgz_cli.onboard.generate import TYPES_BY_COUNT, HandLabels, JointLabel
from dgz_cli.spec.errors import OnboardError
from dgz_cli.spec.io import atomic_write

SCALE_RANGE = (0.6, 1.6)  # per-finger link-length factor
P_REMOVE_TIP = 0.4
P_REMOVE_FINGER = 0.3
FINGER_ORDER = ("thumb", "index", "middle", "ring", "little")


def _scale_vec(text: str | None, s: float, default: str = "0 0 0") -> str:
    return " ".join(f"{float(v) * s:.6g}" for v in (text or default).split())


def _scale_link(link, s: float) -> None:
    """Scale one link's geometry and inertia by ``s`` about the link frame."""
    for tag in ("collision", "visual"):
        for el in link.findall(tag):
            origin = el.find("origin")
            if origin is not None:
                origin.set("xyz", _scale_vec(origin.get("xyz"), s))
            geom = el.find("geometry")
            for g in (list(geom) if geom is not None else []):
                if g.tag == "mesh":
                    g.set("scale", _scale_vec(g.get("scale"), s, "1 1 1"))
                elif g.tag == "box":
                    g.set("size", _scale_vec(g.get("size"), s))
                elif g.tag in ("cylinder", "capsule", "sphere"):
                    for attr in ("radius", "length"):
                        if g.get(attr) is not None:
                            g.set(attr, f"{float(g.get(attr)) * s:.6g}")
    inertial = link.find("inertial")
    if inertial is not None:
        origin = inertial.find("origin")
        if origin is not None:
            origin.set("xyz", _scale_vec(origin.get("xyz"), s))
        mass = inertial.find("mass")
        if mass is not None and mass.get("value") is not None:
            mass.set("value", f"{float(mass.get('value')) * s ** 3:.6g}")
        inertia = inertial.find("inertia")
        if inertia is not None:
            for k, v in inertia.attrib.items():
                inertia.set(k, f"{float(v) * s ** 5:.6g}")


class _Base:
    """The base hand: its sanitized URDF (absolute mesh paths), spec rows and the finger of every link."""

    def __init__(self, spec, urdf: Path, xacro_args: dict[str, str]) -> None:
        from dgz_cli.onboard.urdf import load_kinematics

        self.spec = spec
        self.kin = load_kinematics(urdf, xacro_args)
        nodes = {n.id: n for n in spec.nodes}
        self.row = {r.joint: r for r in spec.joints}
        self.node_of = {r.joint: nodes[r.node] for r in spec.joints}
        self.finger_nodes: dict[str, list] = {}
        for n in spec.nodes:
            if n.type not in ("wrist", "fingertip"):
                self.finger_nodes.setdefault(n.finger, []).append(n)
        joint_finger = {j: n.finger for n in spec.nodes for j in n.joints if n.finger != "wrist"}
        self.link_finger: dict[str, str] = {}
        self.finger_root: dict[str, str] = {}  # finger → its first joint below the palm side
        stack = [(self.kin.root, None)]
        while stack:
            link, finger = stack.pop()
            for j in self.kin.children(link):
                f = joint_finger.get(j.name, finger)
                if f is not None and finger is None:
                    self.finger_root.setdefault(f, j.name)
                if f is not None:
                    self.link_finger[j.child] = f
                stack.append((j.child, f))
        self.mimic_sources = {_mimic_source(j) for j in self.kin.joints.values() if j.mimic is not None}


def _mimic_source(joint) -> str:
    return joint.mimic.joint


def make_variant(base: _Base, seed: int, index: int, name: str) -> tuple[str, HandLabels]:
    rng = np.random.default_rng([seed, index, 13])
    root = etree.fromstring(base.kin.xml)
    fingers = sorted(base.finger_nodes, key=lambda f: FINGER_ORDER.index(f) if f in FINGER_ORDER else 9)
    scale = {f: float(rng.uniform(*SCALE_RANGE)) for f in fingers}
    links = {el.get("name"): el for el in root.findall("link")}
    joints = {el.get("name"): el for el in root.findall("joint")}
    for lname, el in links.items():
        f = base.link_finger.get(lname)
        if f is not None:
            _scale_link(el, scale[f])
    for jname, el in joints.items():
        j = base.kin.joints[jname]
        f = base.link_finger.get(j.parent)
        if f is not None and base.link_finger.get(j.child) == f:
            origin = el.find("origin")
            if origin is not None:
                origin.set("xyz", _scale_vec(origin.get("xyz"), scale[f]))

    removed_joints: set[str] = set()
    fixed_joints: set[str] = set()
    short: set[str] = set()
    # remove a finger whose loss leaves every other finger its class
    non_thumb = [f for f in fingers if f != "thumb"]
    if ("thumb" in fingers and non_thumb == ["index", "middle", "ring", "little"] and "little" in base.finger_root
            and rng.random() < P_REMOVE_FINGER):
        sub = [base.kin.joints[base.finger_root["little"]]] + base.kin.subtree_joints(
            base.kin.joints[base.finger_root["little"]].child)
        names = {j.name for j in sub}
        kept_mimics = [j for j in base.kin.joints.values() if j.mimic is not None and j.name not in names]
        if not any(_mimic_source(j) in names for j in kept_mimics):
            for j in sub:
                root.remove(joints[j.name])
                root.remove(links[j.child])
            removed_joints |= names
            fingers = [f for f in fingers if f != "little"]
    # remove the last node of one finger that has a commanded joint: its joints, and every movable joint below
    # them (mimic followers), become fixed; the links stay
    if rng.random() < P_REMOVE_TIP:
        candidates = {}
        for f in fingers:
            nodes = [n for n in base.finger_nodes[f] if any(j in base.row for j in n.joints)]
            if f == "thumb" or len(nodes) < 2:
                continue
            fix = set(nodes[-1].joints)
            for j in nodes[-1].joints:
                fix |= {k.name for k in base.kin.subtree_joints(base.kin.joints[j].child) if k.type != "fixed"}
            if not any(k.mimic is not None and k.name not in fix and _mimic_source(k) in fix
                       for k in base.kin.joints.values()):
                candidates[f] = fix
        if candidates:
            f = str(rng.choice(sorted(candidates)))
            for jname in sorted(candidates[f]):
                el = joints[jname]
                el.set("type", "fixed")
                for tag in ("axis", "limit", "dynamics", "mimic", "safety_controller", "calibration"):
                    for sub_el in el.findall(tag):
                        el.remove(sub_el)
                fixed_joints.add(jname)
            short.add(f)

    labels = []
    for r in base.spec.joints:
        if r.joint in removed_joints or r.joint in fixed_joints:
            continue
        node = base.node_of[r.joint]
        if node.finger == "wrist":
            idx, ntype = 0, node.type
        else:
            kept = [n for n in base.finger_nodes[node.finger] if not set(n.joints) <= fixed_joints]
            idx = next(i for i, n in enumerate(kept) if n.id == node.id)
            ntype = TYPES_BY_COUNT[len(kept)][idx] if node.finger in short else node.type
        labels.append(JointLabel(joint=r.joint, finger=node.finger, finger_class=node.finger, node=idx,
                                 node_type=ntype, primitive=r.primitive.value, sign=r.sign))
    remaining = {el.get("name") for el in root.findall("joint")}
    mimic = tuple(j.name for j in base.kin.joints.values() if j.mimic is not None and j.name in remaining)
    root.set("name", name)
    text = etree.tostring(root, encoding="unicode")
    what = (f"scales {', '.join(f'{f} ×{scale[f]:.2f}' for f in fingers)}"
            + (f"; removed finger little" if removed_joints else "")
            + (f"; fixed {', '.join(sorted(fixed_joints))}" if fixed_joints else ""))
    head = (f'<?xml version="1.0"?>\n<!-- variant {index} of hand {base.spec.name} (seed {seed}), written by '
            f"dgz hands generate in variants mode: {what}; labels in {name}.labels.json -->\n")
    hl = HandLabels(name=name, seed=seed, kind="variant", side=base.spec.palm.side, joints=tuple(labels), mimic=mimic,
                    palm_normal=None, finger_axis=tuple(float(x) for x in base.spec.palm.finger_axis))
    return head + text + "\n", hl


def write_variants(spec, urdf: Path, out_dir: Path, seed: int, count: int) -> list[tuple[Path, Path]]:
    """Write ``count`` variants of the hand of ``spec`` (its URDF at ``urdf``) as NAME.urdf + NAME.labels.json."""
    base = _Base(spec, urdf, dict(spec.provenance.xacro_args))
    if not base.finger_nodes:
        raise OnboardError(f"{spec.name}: the spec has no finger nodes to vary", "name a hand spec with fingers")
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(count):
        name = f"{spec.name}_v{seed}_{i:04d}"
        text, labels = make_variant(base, seed, i, name)
        u, lab = out_dir / f"{name}.urdf", out_dir / f"{name}.labels.json"
        atomic_write(u, text)
        atomic_write(lab, json.dumps(labels.model_dump(), indent=1) + "\n")
        paths.append((u, lab))
    return paths


__all__ = ["write_variants", "make_variant"]
