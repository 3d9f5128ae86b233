"""Internal consistency checks of a HandSpec (no URDF needed; see onboard/verify.py for those)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from dgz_cli.spec.models import FEATURE_NAMES, NODE_TYPES, HandSpec


@dataclass(frozen=True)
class Finding:
    level: str  # "error" | "warning"
    field: str
    message: str
    fix: str

    def as_dict(self) -> dict:
        return asdict(self)


def lint_spec(spec: HandSpec) -> list[Finding]:
    out: list[Finding] = []

    def err(field: str, msg: str, fix: str) -> None:
        out.append(Finding("error", field, msg, fix))

    p = spec.palm
    vecs = {k: getattr(p, k) for k in ("normal", "finger_axis", "lateral")}
    if not all(len(v) == 3 and all(math.isfinite(x) for x in v) for v in vecs.values()):
        err("palm", "the palm frame has a non-finite or malformed vector", "re-run `dgz onboard`")
    else:
        for k, v in vecs.items():
            norm = math.sqrt(sum(x * x for x in v))
            if abs(norm - 1.0) > 1e-2:
                err(f"palm.{k}", f"palm {k} {v} is not a unit vector (length {norm:.4g})",
                    "re-run `dgz onboard` (or --palm-link) to identify the palm frame")
        n, f, l = vecs["normal"], vecs["finger_axis"], vecs["lateral"]
        cross = [n[1] * f[2] - n[2] * f[1], n[2] * f[0] - n[0] * f[2], n[0] * f[1] - n[1] * f[0]]
        if abs(sum(a * b for a, b in zip(n, f))) > 0.05:
            err("palm.finger_axis", "the palm normal and finger axis are not orthogonal", "re-run `dgz onboard`")
        elif max(abs(a - b) for a, b in zip(cross, l)) > 0.05:
            err("palm.lateral", "palm lateral is not normal × finger_axis", "re-run `dgz onboard`")
    ids = [n.id for n in spec.nodes]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    for i in dup:
        err(f"nodes[{ids.index(i)}].id", f"node id '{i}' is used more than once", "give every node a unique id")
    nodes = {n.id: n for n in spec.nodes}
    roots = [n for n in spec.nodes if n.parent is None]
    if len(roots) != 1 or roots[0].type != "wrist":
        err("nodes", f"the node tree must have exactly one root of type wrist (found {[n.id for n in roots]})",
            "make the wrist node the only node without a parent")
    for k, n in enumerate(spec.nodes):
        if n.parent is not None and n.parent not in nodes:
            err(f"nodes[{k}].parent", f"node '{n.id}' has unknown parent '{n.parent}'", "name an existing node id")
            continue
        seen, cur = set(), n
        while cur.parent is not None and cur.parent in nodes:
            if cur.id in seen:
                err(f"nodes[{k}].parent", f"node '{n.id}' is on a parent cycle", "the node graph must be a tree")
                break
            seen.add(cur.id)
            cur = nodes[cur.parent]
        if n.parent in nodes:
            p = nodes[n.parent]
            if NODE_TYPES.index(n.type) <= NODE_TYPES.index(p.type):
                err(f"nodes[{k}].type", f"node '{n.id}' ({n.type}) follows '{p.id}' ({p.type})",
                    "types must run wrist → metacarpal → proximal → middle → distal → fingertip")
            if p.finger not in ("wrist", n.finger):
                err(f"nodes[{k}].parent", f"node '{n.id}' ({n.finger}) hangs off another finger's node '{p.id}'",
                    "a finger's nodes form one chain from the wrist")
        if n.type == "fingertip" and n.joints:
            err(f"nodes[{k}].joints", f"fingertip node '{n.id}' has joints", "fingertip nodes hold no joints")
        if (n.type == "wrist") != (n.finger == "wrist"):
            err(f"nodes[{k}].finger", f"node '{n.id}': finger '{n.finger}' with type '{n.type}'",
                "only the wrist node has finger class and type 'wrist'")
    for finger in sorted({n.finger for n in spec.nodes} - {"wrist"}):
        tips = [n.id for n in spec.nodes if n.finger == finger and n.type == "fingertip"]
        if len(tips) != 1:
            err("nodes", f"finger '{finger}' has {len(tips)} fingertip nodes", "each finger ends in one fingertip node")
    members = {}
    for n in spec.nodes:
        for j in n.joints:
            if j in members:
                err("nodes", f"joint '{j}' is a member of nodes '{members[j]}' and '{n.id}'", "a joint has one node")
            members[j] = n.id

    names = [r.joint for r in spec.joints]
    for k, r in enumerate(spec.joints):
        if names.count(r.joint) > 1 and names.index(r.joint) == k:
            err(f"joints[{k}].joint", f"joint '{r.joint}' appears {names.count(r.joint)} times in M_h",
                "list each actuated joint once")
        if r.node not in nodes:
            err(f"joints[{k}].node", f"M_h row '{r.joint}' maps to unknown node '{r.node}'", "name an existing node id")
        elif members.get(r.joint) != r.node:
            err(f"joints[{k}].node", f"M_h row '{r.joint}' maps to '{r.node}' but the joint is a member of "
                f"'{members.get(r.joint)}'", "keep nodes[].joints and joints[].node in agreement")
        if r.lower > r.upper:
            err(f"joints[{k}].lower", f"joint '{r.joint}': lower {r.lower} > upper {r.upper}", "swap the limits")
    for k, m in enumerate(spec.mimic):
        if m.source not in names:
            err(f"mimic[{k}].source", f"mimic joint '{m.joint}' follows '{m.source}', which is not in M_h",
                "mimic sources must be actuated joints")
        if m.joint in names:
            err(f"mimic[{k}].joint", f"mimic joint '{m.joint}' is also an M_h row", "a mimic joint is not commanded")

    derived = spec.derived_mask()
    if spec.activation_mask != derived:
        bad = sorted(k for k in set(derived) | set(spec.activation_mask)
                     if spec.activation_mask.get(k) != derived.get(k))
        err(f"activation_mask.{bad[0]}", f"mask row '{bad[0]}' is {spec.activation_mask.get(bad[0])} but M_h implies "
            f"{derived.get(bad[0])}", "re-derive the mask from M_h (re-run `dgz onboard`)")

    feats = spec.features
    if list(feats.names) != FEATURE_NAMES:
        err("features.names", "feature names differ from the 27 of this schema", "re-run `dgz onboard`")
    for nid in ids:
        if nid not in feats.values:
            err(f"features.values.{nid}", f"node '{nid}' has no physical features", "re-run `dgz onboard`")
    for nid, vals in feats.values.items():
        if nid not in nodes:
            err(f"features.values.{nid}", f"features for unknown node '{nid}'", "remove them or re-run `dgz onboard`")
        elif len(vals) != len(FEATURE_NAMES):
            err(f"features.values.{nid}", f"{len(vals)} features, expected {len(FEATURE_NAMES)}", "re-run `dgz onboard`")
        elif not all(math.isfinite(v) and -1.0 <= v <= 1.0 for v in vals):
            bad = next(i for i, v in enumerate(vals) if not (math.isfinite(v) and -1.0 <= v <= 1.0))
            err(f"features.values.{nid}[{bad}]", f"feature {FEATURE_NAMES[bad]} = {vals[bad]} is not finite or "
                f"outside its normalization [-1, 1]", "re-run `dgz onboard`")
    for k, r in enumerate(spec.joints):
        if r.flagged:
            out.append(Finding("warning", f"joints[{k}]", f"joint '{r.joint}' → {r.primitive.value} "
                               f"{'+' if r.sign > 0 else '-'} was flagged as uncertain by the excitation (margin {r.margin:.2f})",
                               "check it in `dgz show`; confirm or correct it in an --overrides file"))
    return out
