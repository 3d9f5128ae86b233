"""Unit-joint excitation in MuJoCo → (primitive, sign, margin) for every movable joint (Supp. S1-B).

For joint j, its value is moved by a small δ with every other actuated joint fixed (mimic
joints follow their source, as the equality constraints would make them) and the induced
motion of the child unit is measured in the palm frame: the unit's point t is the fingertip of
j's finger (the centroid of all fingertips for wrist joints). With r = t − anchor(j), the motion
is split into three scores whose squares sum to one for a pure rotation:

- FLEX: tip translation along n' (the palm normal made orthogonal to r), per unit lever;
- ABD:  tip translation along m = r̂ × n' (in-plane, sideways), per unit lever;
- ROT:  rotation about r̂ itself (torsion of the unit about its own long axis).

The largest score names the primitive; margin = largest − second. A non-thumb joint that is a
pure twist at the rest pose (Allegro-style finger roots) is excited again with the finger half
flexed: if the twist then moves the fingertip sideways, it is ABD. The reference normal is n;
for a digit of a radial hand (claw, opposed digits, jaw) the direction from its tip toward the
grasp axis, so each digit's signs come from its own excitation; for the thumb the direction to
the index tip, except that its primitive is decided by its own curl axis (the axis of its last
revolute joint) when the two disagree. Signs follow design.md: +FLEX moves the tip towards the
reference; +ABD moves it away from the middle finger (sides read in the open hand; the middle
finger and the wrist: towards the thumb; the thumb: opens the thumb-finger angle for swings in
the palm plane, +n for palmar ones); +ROT turns the digit's pad (its +n' side) towards the
opposing digit (thumb → the other fingertips, fingers → the thumb).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgz_cli.onboard.compile import Poser
from dgz_cli.onboard.frame import PalmFrame, tip_positions
from dgz_cli.onboard.structure import Structure
from dgz_cli.onboard.urdf import Kinematics
from dgz_cli.spec.kinematics import rest_pose

PRIMITIVES = ("FLEX", "ABD", "ROT")
ROT_SWEEP_WEAK = 0.062  # thumb ROT: a gap change below this per unit of tip travel leaves the sign undecided
THUMB_WEAK = 0.3  # a thumb motion whose component toward the opposed fingertip is below this is judged by +n


@dataclass(frozen=True)
class ExcitationSettings:
    delta: float = 0.02  # rad (or m for prismatic joints)
    flexed_fraction: float = 0.5  # of the closing range, for the re-excitation of twisting roots
    margin_threshold: float = 0.2  # decisions with a smaller margin are flagged


@dataclass(frozen=True)
class Response:
    joint: str
    primitive: str
    sign: int
    margin: float
    scores: tuple[float, float, float]
    flagged: bool
    note: str


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else v * 0.0


def _rotvec(r0: np.ndarray, r1: np.ndarray) -> np.ndarray:
    """Rotation vector of r1·r0ᵀ (small angles)."""
    d = r1 @ r0.T
    return 0.5 * np.array([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]])


class Exciter:
    def __init__(self, kin: Kinematics, poser: Poser, st: Structure, frame: PalmFrame,
                 settings: ExcitationSettings) -> None:
        self.kin, self.poser, self.st, self.frame, self.cfg = kin, poser, st, frame, settings
        self.finger_of: dict[str, int] = {}
        for i, c in enumerate(st.chains):
            for j in c.joints:
                self.finger_of[j] = i
        self.classes = frame.fingers
        self._thumb_axis: dict[int, tuple[str, np.ndarray] | None] = {}
        self._open_tips: np.ndarray | None = None

    def _unit_point(self, joint: str) -> tuple[np.ndarray, str | None]:
        i = self.finger_of.get(joint)
        tips = tip_positions(self.poser, self.st)
        if i is None:
            return tips.mean(0), None
        return tips[i], self.st.chains[i].tip_link

    def _motion(self, q: dict[str, float], joint: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(tip velocity, tip-body angular velocity, anchor, tip) per unit joint velocity at pose q."""
        j = self.kin.joints[joint]
        self.poser.pose(q)
        t0, tip_link = self._unit_point(joint)
        anchor = self.poser.joint_anchor(joint)
        rot_link = tip_link or self.st.chains[0].tip_link
        r0 = self.poser.link_rot(rot_link)
        value = self.poser.value(joint)
        step = self.cfg.delta if value + self.cfg.delta <= j.upper or j.type == "continuous" else -self.cfg.delta
        q1 = dict(q)
        if j.actuated:
            q1[joint] = value + step
            self.poser.pose(q1)
        else:  # a mimic joint excited on its own (used to group nodes only)
            self.poser.pose(q, extra={joint: step})
        t1, _ = self._unit_point(joint)
        w = _rotvec(r0, self.poser.link_rot(rot_link)) / step
        if tip_link is None:  # wrist joints move the whole hand: use the palm link's rotation
            w = self.poser.joint_axis(joint) if j.type != "prismatic" else np.zeros(3)
        self.poser.pose(q)
        return (t1 - t0) / step, w, anchor, t0

    def scores(self, q: dict[str, float], joint: str, ref: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        v, w, anchor, tip = self._motion(q, joint)
        r = tip - anchor
        lever = float(np.linalg.norm(r))
        rh = _unit(r)
        n = self._reference_normal(joint) if ref is None else ref
        n_perp = _unit(n - (n @ rh) * rh)
        m = np.cross(rh, n_perp)
        s = np.array([v @ n_perp / max(lever, 1e-6), v @ m / max(lever, 1e-6), w @ rh])
        if self.kin.joints[joint].type == "prismatic":
            s[:2] = [v @ n_perp, v @ m]
        return s, v, w, n_perp

    def _is_thumb(self, joint: str) -> bool:
        i = self.finger_of.get(joint)
        return i is not None and self.classes[i] == "thumb"

    def _opposed_target(self) -> np.ndarray:
        """The point a thumb closes toward: the index fingertip, else the mean non-thumb fingertip."""
        tips = tip_positions(self.poser, self.st)
        if "index" in self.classes:
            return tips[self.classes.index("index")]
        return tips[[k for k, c in enumerate(self.classes) if c != "thumb"]].mean(0)

    def _reference_normal(self, joint: str) -> np.ndarray:
        """The direction 'closing' moves a unit toward: +n; for a digit of a radial hand (claw, jaw) the grasp
        axis; for the thumb its own curl (see :meth:`_thumb_curl`)."""
        i = self.finger_of.get(joint)
        if i is None:
            return self.frame.normal
        if self._is_thumb(joint):
            tips = tip_positions(self.poser, self.st)
            return _unit(self._opposed_target() - tips[i])
        if self.frame.radial:
            return self.frame.toward_axis(tip_positions(self.poser, self.st)[i])
        return self.frame.normal

    def _thumb_curl(self, joint: str) -> np.ndarray | None:
        """The thumb's own curl at ``joint`` (current pose): the direction the thumb tip moves about the thumb's
        curl axis taken at ``joint``'s anchor. The curl axis is the axis of the thumb's last revolute joint,
        oriented once per thumb at the rest pose so that curling moves the tip toward the palm side (+n), or,
        when that barely changes, toward the opposed fingertip. None for a thumb without a revolute joint."""
        i = self.finger_of[joint]
        if i not in self._thumb_axis:
            chain = self.st.chains[i]
            last = next((j for j in reversed(chain.joints) if self.kin.joints[j].type != "prismatic"), None)
            axis = None
            if last is not None:
                self.poser.pose(self.poser.rest())
                own = tip_positions(self.poser, self.st)[i]
                axis = self.poser.joint_axis(last)
                curl = _unit(np.cross(axis, own - self.poser.joint_anchor(last)))
                d = curl @ self.frame.normal
                if abs(d) < THUMB_WEAK:
                    d = curl @ _unit(self._opposed_target() - own)
                axis = axis if d >= 0 else -axis
                # axes are world vectors at the rest pose: keep the axis in the last joint's frame
                axis = (last, self.poser.link_rot(self.kin.joints[last].child).T @ axis)
            self._thumb_axis[i] = axis
        ax = self._thumb_axis[i]
        if ax is None:
            return None
        last, local = ax
        axis = self.poser.link_rot(self.kin.joints[last].child) @ local
        own = tip_positions(self.poser, self.st)[i]
        curl = _unit(np.cross(axis, own - self.poser.joint_anchor(joint)))
        return curl if np.linalg.norm(curl) > 1e-9 else None

    def _rest_tips(self) -> np.ndarray:
        if self._open_tips is None:
            current = {n: self.poser.value(n) for n in self.poser.actuated}
            self.poser.pose(self.poser.rest())
            self._open_tips = tip_positions(self.poser, self.st)
            self.poser.pose(current)
        return self._open_tips

    def _opening(self, thumb: int, v: np.ndarray) -> float:
        """How much tip velocity ``v`` opens the angle between the thumb (first joint → tip) and the fingers'
        direction f: > 0 opens, in units of |v|."""
        tips = tip_positions(self.poser, self.st)
        t = _unit(tips[thumb] - self.poser.joint_anchor(self.st.chains[thumb].joints[0]))
        f = self.frame.finger_axis
        perp = f - (f @ t) * t
        if np.linalg.norm(perp) < 1e-6:
            return 0.0
        return float(-(v @ _unit(perp)))

    def _sign(self, prim: str, joint: str, v: np.ndarray, w: np.ndarray, n_perp: np.ndarray,
              ref: np.ndarray | None = None) -> tuple[int, float]:
        """(sign, strength ∈ [0,1]) of the joint's + direction for primitive ``prim``."""
        fr = self.frame
        i = self.finger_of.get(joint)
        cls = self.classes[i] if i is not None else "wrist"
        tips = tip_positions(self.poser, self.st)
        own = tips[i] if i is not None else tips.mean(0)
        idx = {c: k for k, c in enumerate(self.classes)}
        non_thumb = [k for k, c in enumerate(self.classes) if c != "thumb"]
        if prim == "FLEX":
            d = v @ (self._reference_normal(joint) if ref is None else ref)
            return (1 if d >= 0 else -1), abs(d) / max(np.linalg.norm(v), 1e-9)
        if prim == "ABD":
            if cls == "thumb":
                # a swing within the palm plane opens the angle between thumb and index finger; palmar abduction
                # (out of the palm plane) is +n; the gap to the index tip decides when the angle barely changes
                speed = np.linalg.norm(v)
                palmar = abs(v @ fr.normal) >= 0.5 * speed
                d = v @ fr.normal if palmar else self._opening(i, v)
                if abs(d) < THUMB_WEAK * speed:
                    d = v @ _unit(own - self._opposed_target())
                if abs(d) < THUMB_WEAK * speed:
                    d = v @ fr.normal
            else:
                if cls in ("middle", "wrist"):
                    target = tips[idx["thumb"]] if "thumb" in idx else None
                    away = (target - own) if target is not None else fr.lateral
                else:  # which side of the middle finger is 'away' is read in the open hand (rest pose): long
                    # claw digits excited half-flexed may have crossed the middle finger's line
                    open_tips = self._rest_tips()
                    ref = open_tips[idx["middle"]] if "middle" in idx else open_tips[non_thumb].mean(0)
                    away = open_tips[i] - ref
                    if abs(away @ fr.lateral) < 1e-6:
                        away = own - (tips[idx["middle"]] if "middle" in idx else tips[non_thumb].mean(0))
                d = (v @ fr.lateral) * np.sign(away @ fr.lateral)
            return (1 if d >= 0 else -1), min(1.0, abs(d) / max(np.linalg.norm(v), 1e-9))
        if cls == "thumb":  # +ROT (opposition) brings the (half-flexed) thumb tip toward the opposed fingertip
            d = v @ _unit(self._opposed_target() - own)
            return (1 if d >= 0 else -1), min(1.0, abs(d) / max(np.linalg.norm(v), 1e-9))
        # ROT: turn the pad (+n' side) towards the opposing digit(s)
        if cls == "thumb":
            goal = tips[non_thumb].mean(0) - own
        elif "thumb" in idx:
            goal = tips[idx["thumb"]] - own
        else:
            goal = tips.mean(0) - own
        dpad = np.cross(w, n_perp)
        d = dpad @ _unit(goal)
        return (1 if d >= 0 else -1), min(1.0, abs(d) / max(np.linalg.norm(w), 1e-9))

    def classify(self, joint: str, first_pass: dict[str, Response] | None = None) -> Response:
        q = self.poser.rest()
        s, v, w, n_perp = self.scores(q, joint)
        a = np.abs(s) / max(float(np.linalg.norm(s)), 1e-12)
        order = np.argsort(-a)
        prim, margin, note = PRIMITIVES[order[0]], float(a[order[0]] - a[order[1]]), "rest pose"
        i = self.finger_of.get(joint)
        curl = self._thumb_curl(joint) if self._is_thumb(joint) else None
        if curl is not None:
            # the thumb's own curl axis decides its primitive; opposition (the reference above) gives the scores
            # and sign when it agrees, the curl when it does not (a diagonal thumb beside the palm)
            s2, v2, w2, n2 = self.scores(q, joint, ref=curl)
            a2 = np.abs(s2) / max(float(np.linalg.norm(s2)), 1e-12)
            o2 = np.argsort(-a2)
            if o2[0] != order[0]:
                prim, margin = PRIMITIVES[o2[0]], float(a2[o2[0]] - a2[o2[1]])
                if prim != "ROT":
                    sign, strength = self._sign(prim, joint, v2, w2, n2, ref=curl)
                    self.poser.pose(q)
                    return self._response(joint, prim, sign, margin, a2, strength,
                                          "rest pose; judged by the thumb's own curl axis")
                a, note = a2, "rest pose; judged by the thumb's own curl axis"
        if prim == "ROT" and first_pass is not None and i is not None and self.classes[i] != "thumb":
            q_flex = self._flexed_pose(joint, first_pass)
            if q_flex is not None:
                s2, v2, w2, n2 = self.scores(q_flex, joint)
                a2 = np.abs(s2) / max(float(np.linalg.norm(s2)), 1e-12)
                sideways = float(np.hypot(a2[0], a2[1]))
                if sideways > a2[2]:
                    prim, margin, note = "ABD", sideways - float(a2[2]), "twist at rest, spreads when flexed"
                    self.poser.pose(q_flex)
                    sign, strength = self._sign("ABD", joint, v2, w2, n2)
                    self.poser.pose(q)
                    return self._response(joint, prim, sign, margin, a2, strength, note)
        if prim == "ROT" and first_pass is not None and self._is_thumb(joint):
            result = self._opposition_sign(joint, first_pass)
            if result is not None:  # opposition: the twist after which a closing thumb lands nearer the index
                sign, strength = result
                self.poser.pose(q)
                return self._response(joint, prim, sign, margin, a, strength, note + "; sign by opposition test")
        self.poser.pose(q)
        sign, strength = self._sign(prim, joint, v, w, n_perp)
        return self._response(joint, prim, sign, margin, a, strength, note)

    def _response(self, joint, prim, sign, margin, a, strength, note) -> Response:
        flagged = margin < self.cfg.margin_threshold or strength < 0.1
        if strength < 0.1:
            note += "; sign weakly determined"
        return Response(joint, prim, int(sign), round(float(margin), 4),
                        tuple(round(float(x), 4) for x in a), bool(flagged), note)

    def _opposition_sign(self, joint: str, first: dict[str, "Response"]) -> tuple[int, float] | None:
        """+ROT on the thumb = the twist direction after which closing the thumb's FLEX joints brings
        its tip nearer the opposed fingertip. Returns (sign, relative strength) or None."""
        j = self.kin.joints[joint]
        if not j.actuated:
            return None
        gaps, ends = {}, {}
        for s in (1, -1):
            q_flex = self._flexed_pose(joint, first)
            if q_flex is None:
                return None
            q_flex[joint] = float(np.clip(q_flex[joint] + s * 0.3, j.lower, j.upper))
            self.poser.pose(q_flex)
            ends[s] = tip_positions(self.poser, self.st)[self.finger_of[joint]]
            gaps[s] = float(np.linalg.norm(ends[s] - self._opposed_target()))
        sign = 1 if gaps[1] < gaps[-1] else -1
        # how much of the tip's sweep closes the gap: the change of the gap per unit of tip travel. Relative to the
        # tip's own travel, not to the gap, so it does not shrink when the thumb (or its gap) grows: a thumb whose
        # sweep passes the opposed tip tangentially changes the gap little per unit of travel, whatever its length
        travel = float(np.linalg.norm(ends[1] - ends[-1]))
        strength = min(1.0, abs(gaps[1] - gaps[-1]) / max(travel, 1e-9) * (0.1 / ROT_SWEEP_WEAK))
        if strength < 0.1:  # no clear winner: the wider side of the range is the functional one (flagged)
            rest = float(rest_pose(j.lower, j.upper))
            sign = 1 if (j.upper - rest) >= (rest - j.lower) else -1
        return sign, strength

    def _flexed_pose(self, joint: str, first: dict[str, Response]) -> dict[str, float] | None:
        chain = self.st.chains[self.finger_of[joint]].joints
        below = chain[chain.index(joint) + 1:]
        q = self.poser.rest()
        moved = False
        for name in below:
            r = first.get(name)
            j = self.kin.joints[name]
            if r is None or r.primitive != "FLEX" or not j.actuated:
                continue
            # r.sign = +1 means +q closes; move towards the closing limit
            lim = j.upper if r.sign > 0 else j.lower
            q[name] = q[name] + self.cfg.flexed_fraction * (lim - q[name])
            moved = True
        return q if moved else None

    def run(self) -> dict[str, Response]:
        movable = [n for n, j in self.kin.joints.items() if j.movable and n not in self.st.excluded_joints]
        first = {n: self.classify(n) for n in movable}
        return {n: (self.classify(n, first) if first[n].primitive == "ROT" else first[n]) for n in movable}
