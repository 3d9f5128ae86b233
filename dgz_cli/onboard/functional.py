"""The functional check that defines a "correct" M_h better than any label (design.md).

A primitive command α is pushed through M_h (Δq_j = s_j · α[n_j, p_j], clipped to the limits):
1. from the rest pose, +FLEX (0.5 rad) on every node moves every fingertip closer to the palm centre;
   (a thumb lying beside the palm may instead move mostly toward the palm side, +n);
2. from a half-closed pose (+FLEX 0.5 rad, where finger-root twists become spreads), +ABD
   (0.15 rad) on a non-middle, non-thumb finger moves its tip away from the middle finger's
   axis, and +ABD on all nodes spreads fingertips on opposite sides of the middle finger apart;
   "away" is judged by the sides the fingertips lie on in the open hand: long claw digits may
   have crossed each other's line at the half-closed pose;
3. from the rest pose, +FLEX and +ROT (0.3 rad) on the thumb's nodes bring the thumb tip toward
   the index tip (or the nearest other fingertip when there is no index), or toward that finger
   (its base → tip segment), or mostly toward the palm side (+n) for a thumb beside the palm.
Distances are measured in the palm link's frame, so wrist joints do not fool the check.

:func:`rot_warnings` adds a softer test of the thumb's ROT sign alone (a warning, not a refusal: on real hands the
twist's effect on the tip is small, e.g. 2–4 mm of gap over 24–28 mm of tip travel on Allegro and Shadow).
"""

from __future__ import annotations

import itertools

import numpy as np

from dgz_cli.spec.models import HandSpec

CLOSE, SPREAD, OPPOSE = 0.5, 0.15, 0.3  # rad of primitive command per check


def _tips(spec: HandSpec, poser) -> dict[str, np.ndarray]:
    rot, pos = poser.link_rot(spec.palm.link), poser.link_pos(spec.palm.link)
    return {n.finger: rot.T @ (poser.link_pos(n.anchor_link, np.array(n.anchor_point)) - pos)
            for n in spec.nodes if n.type == "fingertip"}


def _command(spec: HandSpec, q: dict[str, float], prims: set[str], fingers: set[str] | None,
             step: float) -> dict[str, float]:
    finger_of = {n.id: n.finger for n in spec.nodes}
    q = dict(q)
    for r in spec.joints:
        if r.primitive.value in prims and (fingers is None or finger_of[r.node] in fingers):
            q[r.joint] = float(np.clip(q[r.joint] + r.sign * step, r.lower, r.upper))
    return q


def _apply(spec: HandSpec, poser, prims: set[str], fingers: set[str] | None, step: float,
           start: dict[str, float] | None = None) -> dict[str, np.ndarray]:
    poser.pose(_command(spec, start if start is not None else poser.rest(), prims, fingers, step))
    return _tips(spec, poser)


def _finger_base(spec: HandSpec, poser, finger: str) -> np.ndarray:
    """Palm-frame position of a finger's first node anchor (at the current pose)."""
    node = next(n for n in spec.nodes if n.finger == finger and n.parent == "wrist")
    rot, pos = poser.link_rot(spec.palm.link), poser.link_pos(spec.palm.link)
    return rot.T @ (poser.link_pos(node.anchor_link, np.array(node.anchor_point)) - pos)


def _to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = float(np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))


def _palmward(move: np.ndarray, normal: np.ndarray) -> bool:
    """The motion goes mostly toward the palm side (+n)."""
    return bool(move @ normal > 0.5 * np.linalg.norm(move) > 0)


def functional_check(spec: HandSpec, poser) -> list[str]:
    """Return one message per violated expectation (empty list = pass)."""
    problems: list[str] = []
    poser.pose(poser.rest())
    rest = _tips(spec, poser)
    center = np.array(spec.palm.center)
    lateral = np.array(spec.palm.lateral)
    normal = np.array(spec.palm.normal)
    fingers_with = {p: {n.finger for n in spec.nodes for r in spec.joints if r.node == n.id and r.primitive.value == p}
                    for p in ("FLEX", "ABD", "ROT")}

    closed = _apply(spec, poser, {"FLEX"}, None, CLOSE)
    for finger, tip in rest.items():
        if finger not in fingers_with["FLEX"] or np.linalg.norm(closed[finger] - center) < np.linalg.norm(tip - center):
            continue
        if finger == "thumb" and _palmward(closed[finger] - tip, normal):
            continue  # a thumb beside the palm closes toward the palm side first
        problems.append(f"+FLEX does not move the {finger} fingertip closer to the palm centre")

    others = [f for f in rest if f not in ("middle", "thumb") and f in fingers_with["ABD"]]
    open_tips = rest
    half = _command(spec, poser.rest(), {"FLEX"}, None, CLOSE)
    poser.pose(half)
    rest = _tips(spec, poser)

    def side(a: str, b: str) -> float:
        """Which side of b along l fingertip a lies on in the open hand (rest pose). Long digits of a claw
        can cross each other's line on the way to the half-closed pose: the open hand's side still says which
        way is 'away'."""
        s = (open_tips[a] - open_tips[b]) @ lateral
        return float(np.sign(s if abs(s) > 1e-6 else (rest[a] - rest[b]) @ lateral))

    def crossed(a: str, b: str) -> bool:
        return float(np.sign((rest[a] - rest[b]) @ lateral)) != side(a, b)

    if "middle" in rest:
        for finger in others:
            spread = _apply(spec, poser, {"ABD"}, {finger}, SPREAD, half)
            if crossed(finger, "middle"):
                away = ((spread[finger] - rest[finger]) @ lateral) * side(finger, "middle") > 0
            else:
                away = abs((spread[finger] - rest["middle"]) @ lateral) > abs((rest[finger] - rest["middle"]) @ lateral)
            if not away:
                problems.append(f"+ABD does not move the {finger} fingertip away from the middle finger")
    spread = _apply(spec, poser, {"ABD"}, None, SPREAD, half)
    for a, b in itertools.combinations(others, 2):
        if "middle" in rest and side(a, "middle") * side(b, "middle") > 0:
            continue  # same side of the middle finger: both move the same way, their gap may shrink
        if crossed(a, b):
            apart = ((spread[a] - spread[b]) - (rest[a] - rest[b])) @ lateral * side(a, b) > 0
        else:
            apart = np.linalg.norm(spread[a] - spread[b]) > np.linalg.norm(rest[a] - rest[b])
        if not apart:
            problems.append(f"+ABD does not spread the {a} and {b} fingertips apart")

    poser.pose(poser.rest())
    rest = _tips(spec, poser)
    if "thumb" in rest and fingers_with["FLEX"] | fingers_with["ROT"] >= {"thumb"}:
        target = "index" if "index" in rest else min((f for f in rest if f != "thumb"),
                                                     key=lambda f: np.linalg.norm(rest[f] - rest["thumb"]))
        base = _finger_base(spec, poser, target)
        opposed = _apply(spec, poser, {"FLEX", "ROT"}, {"thumb"}, OPPOSE)
        nearer = np.linalg.norm(opposed["thumb"] - rest[target]) < np.linalg.norm(rest["thumb"] - rest[target])
        # a thumb lying beside the palm curls toward the palm side (+n), or across toward the finger, first
        finger = _to_segment(opposed["thumb"], base, rest[target]) < _to_segment(rest["thumb"], base, rest[target])
        if not (nearer or finger or _palmward(opposed["thumb"] - rest["thumb"], normal)):
            problems.append(f"thumb +FLEX/+ROT brings the thumb tip neither toward the {target} finger nor toward "
                            "the palm side")
    poser.pose(poser.rest())
    return problems


ROT_AWAY, ROT_MIN_TRAVEL = 0.05, 0.005  # gap change per unit of tip travel; m of tip travel between ±ROT


def rot_warnings(spec: HandSpec, poser) -> list[str]:
    """With the thumb half-closed (+FLEX 0.5 rad through M_h), +ROT (0.3 rad) should not leave its tip farther
    from the index tip (or the nearest other fingertip) than −ROT does. Warn when it does by more than ROT_AWAY
    per unit of the tip's travel between the two (a travel under ROT_MIN_TRAVEL is a pure twist: not judged)."""
    poser.pose(poser.rest())
    rest = _tips(spec, poser)
    finger_of = {n.id: n.finger for n in spec.nodes}
    if "thumb" not in rest or not any(r.primitive.value == "ROT" and finger_of[r.node] == "thumb" for r in spec.joints):
        return []
    target = "index" if "index" in rest else min((f for f in rest if f != "thumb"),
                                                 key=lambda f: np.linalg.norm(rest[f] - rest["thumb"]))
    half = _command(spec, poser.rest(), {"FLEX"}, {"thumb"}, CLOSE)
    ends = {s: _apply(spec, poser, {"ROT"}, {"thumb"}, s * OPPOSE, half)["thumb"] for s in (1, -1)}
    poser.pose(poser.rest())
    travel = float(np.linalg.norm(ends[1] - ends[-1]))
    away = float(np.linalg.norm(ends[1] - rest[target]) - np.linalg.norm(ends[-1] - rest[target]))
    if travel < ROT_MIN_TRAVEL or away <= ROT_AWAY * travel:
        return []
    return [f"thumb +ROT leaves the half-closed thumb tip {away * 1000:.1f} mm farther from the {target} fingertip "
            f"than -ROT does (tip travel {travel * 1000:.1f} mm): the ROT sign may be flipped"]
