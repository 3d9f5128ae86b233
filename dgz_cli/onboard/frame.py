"""Palm frame, thumb detection, finger classes and side, estimated from the kinematics.

Rules (documented in docs/onboarding.md):
- curl_i: at the rest pose, the direction fingertip i moves when its last joint closes
  (revolute: toward the wider side of that joint's range; prismatic: toward the other fingertips).
- dir_i: from digit i's first joint to the centre of its last link's collision geometry.
- Thumb: the digit that agrees least with the others, agreement = mean over the others of
  min(cos curl, cos dir); it must agree < 0.95, stand out from the runner-up by > 0.02, and the
  other digits must all curl to one side (no two close toward each other, as on a claw). A
  runner-up within 0.01-0.02 is refused by name (the thumb is ambiguous).
- Radial hands (no thumb, |mean curl| < 0.5: claws, opposed digits, parallel jaws): f from the
  palm centre to the mean fingertip (the grasp axis), n from the first digit's tip toward that
  axis, l = n × f; classes by angle about f.
- Otherwise: a = the mean closing axis of the non-thumb fingers' last joints; f: from the palm
  centre (centroid of the palm's collision geometry) towards the non-thumb fingertips, orthogonal
  to a; n = a × f (the side the fingers curl to); l = n × f. Palm frame axes: x = f, y = l, z = n.
- Side: right when the thumb base lies on the −l side of the other finger bases.
- Classes across the palm from the thumb side: 4 fingers index..little, 3 index..ring,
  2 middle/ring, 1 middle (Barrett = thumb/middle/ring, as in the paper).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgz_cli.onboard.compile import Poser
from dgz_cli.onboard.structure import Structure, rigid_group
from dgz_cli.onboard.urdf import Kinematics
from dgz_cli.spec.errors import OnboardError
from dgz_cli.spec.kinematics import rest_pose

THUMB_AGREE = 0.95  # a thumb agrees with the other digits less than this (mean cosine of curl and direction)
THUMB_MARGIN = 0.02  # ... and less than the runner-up by more than this
RADIAL = 0.5  # |mean curl| below this: the digits close toward each other (no common palm side)
CLASS_NAMES = {1: ["middle"], 2: ["middle", "ring"], 3: ["index", "middle", "ring"],
               4: ["index", "middle", "ring", "little"]}


@dataclass(frozen=True)
class PalmFrame:
    """World-frame palm axes at the rest pose (unit 3-vectors) and the palm centre (m)."""

    center: np.ndarray
    normal: np.ndarray  # n
    finger_axis: np.ndarray  # f
    lateral: np.ndarray  # l = n × f
    side: str
    fingers: tuple[str, ...]  # class per chain, aligned with Structure.chains
    thumb_margin: float
    radial: bool = False  # the digits close toward a common axis from different sides (claw, jaw)

    def toward_axis(self, p: np.ndarray) -> np.ndarray:
        """Unit direction from point ``p`` toward the grasp axis (the line through the centre along f)."""
        off = (p - self.center) - ((p - self.center) @ self.finger_axis) * self.finger_axis
        return _unit(-off)

    def to_palm(self, v: np.ndarray) -> np.ndarray:
        """World direction → palm-frame coordinates (f, l, n)."""
        return np.array([v @ self.finger_axis, v @ self.lateral, v @ self.normal])


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else v * 0.0


def closing_sign(kin: Kinematics, joint: str) -> float:
    j = kin.joints[joint]
    rest = float(rest_pose(j.lower, j.upper))
    return 1.0 if (j.upper - rest) >= (rest - j.lower) else -1.0


def tip_positions(poser: Poser, st: Structure) -> np.ndarray:
    """World fingertip positions (F, 3) at the current pose."""
    return np.array([poser.link_pos(c.tip_link, c.tip_point) for c in st.chains])


def _curls(kin: Kinematics, poser: Poser, st: Structure, tips: np.ndarray) -> np.ndarray:
    """curl_i: the direction fingertip i moves when its last joint closes. A revolute joint closes toward the
    wider side of its range; a prismatic digit (a jaw) closes toward the other fingertips."""
    curls = []
    for i, (c, t) in enumerate(zip(st.chains, tips)):
        last = c.joints[-1]
        if kin.joints[last].type == "prismatic":
            axis = poser.joint_axis(last)
            toward = np.delete(tips, i, axis=0).mean(0) - t if len(tips) > 1 else axis
            v = axis if axis @ toward >= 0 else -axis
        else:
            v = np.cross(poser.joint_axis(last) * closing_sign(kin, last), t - poser.joint_anchor(last))
        curls.append(_unit(v))
    return np.array(curls)


class ThumbAmbiguous(Exception):
    def __init__(self, first: int, second: int, margin: float) -> None:
        self.first, self.second, self.margin = first, second, margin


def _distal_centre(kin: Kinematics, poser: Poser, chain, tip: np.ndarray) -> np.ndarray:
    """Centre of the collision geometry of a digit's last link (its fingertip when it has none): where the digit
    points, without the sideways offset a box corner chosen as fingertip point would add."""
    pts = poser.geom_points(rigid_group(kin, kin.joints[chain.joints[-1]].child))
    return pts.mean(0) if len(pts) else tip


def find_thumb(curls: np.ndarray, dirs: np.ndarray) -> tuple[int | None, float]:
    """The digit that agrees least with the others in how it curls and where it points (mean of the two
    cosines over the other digits), if it stands out and the other digits all curl to one side (no two of
    them close toward each other, as on a claw): (index, margin over the runner-up) or (None, margin)."""
    nf = len(curls)
    if nf < 3:
        return None, 0.0
    cos = np.minimum(curls @ curls.T, dirs @ dirs.T)
    agree = (cos.sum(1) - 1.0) / (nf - 1)
    order = np.argsort(agree, kind="stable")
    margin = float(agree[order[1]] - agree[order[0]])
    rest = [int(i) for i in order[1:]]
    mutual = min(float(curls[i] @ curls[j]) for i in rest for j in rest if i < j)
    if agree[order[0]] < THUMB_AGREE and mutual > 0:  # the others close to one side
        if margin > THUMB_MARGIN:
            return int(order[0]), margin
        if margin > THUMB_MARGIN / 2:
            raise ThumbAmbiguous(int(order[0]), int(order[1]), margin)
    return None, margin


def estimate(kin: Kinematics, poser: Poser, st: Structure) -> PalmFrame:
    poser.pose(poser.rest())
    tips = tip_positions(poser, st)
    bases = np.array([poser.joint_anchor(c.joints[0]) for c in st.chains])
    curls = _curls(kin, poser, st, tips)
    dirs = np.array([_unit(_distal_centre(kin, poser, c, t) - b) for c, t, b in zip(st.chains, tips, bases)])
    nf = len(st.chains)
    try:
        thumb, margin = find_thumb(curls, dirs)
    except ThumbAmbiguous as amb:
        a, b = (st.chains[amb.first].joints[0], st.chains[amb.second].joints[0])
        raise OnboardError(f"{kin.source}: cannot tell which digit is the thumb: the chains starting at joints '{a}' "
                           f"and '{b}' differ from the other digits almost equally (margin {amb.margin:.3f})",
                           "dgz takes as thumb the digit that curls and points unlike the others at the rest pose "
                           "(0 in every range); check that pose and the joint ranges") from None
    others = [i for i in range(nf) if i != thumb]

    pts = poser.geom_points(list(st.palm_group))
    center = pts.mean(0) if len(pts) else poser.link_pos(st.palm_link)
    radial = thumb is None and nf >= 2 and float(np.linalg.norm(curls.mean(0))) < RADIAL
    if radial:
        # The digits close toward a common axis from different sides (a claw, two opposed digits, a parallel
        # jaw): f runs from the palm centre to the mean fingertip (the grasp axis); n is the direction from
        # the first digit's tip toward that axis (any choice orthogonal to f is as good: no digit is special).
        f = _unit(tips.mean(0) - center)
        n = np.zeros(3)
        for t in tips:
            off = (t - center) - ((t - center) @ f) * f
            if np.linalg.norm(off) > 1e-4:
                n = _unit(-off)
                break
        if np.linalg.norm(f) < 1e-6 or np.linalg.norm(n) < 1e-6:
            raise OnboardError(f"{kin.source}: the palm frame is undefined (the fingertips surround no axis "
                               f"in front of the palm)", "check --palm-link; the palm must lie behind the fingers")
        l = np.cross(n, f)
        across = sorted(others, key=lambda i: float(np.arctan2((bases[i] - center) @ l, (bases[i] - center) @ n)))
        return _named(kin, center, n, f, l, "right", nf, None, across, margin, radial=True)
    # The non-thumb fingers curl about a common flexion axis a (their last joints): l = −a.
    flex_axes = [poser.joint_axis(st.chains[i].joints[-1]) * closing_sign(kin, st.chains[i].joints[-1])
                 for i in others if kin.joints[st.chains[i].joints[-1]].type != "prismatic"]
    a = _unit(np.sum(flex_axes, axis=0)) if flex_axes else np.zeros(3)
    reach = tips[others].mean(0) - center
    if np.linalg.norm(a) < 1e-6:  # no common flexion axis (prismatic fingers): fall back to the curls
        n = _unit(curls.sum(0))
        f = _unit(reach - (reach @ n) * n)
    else:
        f = _unit(reach - (reach @ a) * a)
        n = np.cross(a, f)
    if np.linalg.norm(f) < 1e-6 or np.linalg.norm(n) < 1e-6:
        raise OnboardError(f"{kin.source}: the palm frame is undefined (fingers point along their flexion axis)",
                           "check --palm-link; dgz needs fingers that curl about a common axis")
    if n @ curls.sum(0) < 0:  # n must point to the side the hand closes toward
        n = -n
    l = np.cross(n, f)

    side = "right"
    if thumb is not None and others:
        offset = (bases[thumb] - bases[others].mean(0)) @ l
        side = "right" if offset <= 0 else "left"
    across = sorted(others, key=lambda i: (bases[i] @ l) * (1 if side == "right" else -1))
    return _named(kin, center, n, f, l, side, nf, thumb, across, margin)


def _named(kin: Kinematics, center, n, f, l, side: str, nf: int, thumb: int | None, across: list[int],
           margin: float, radial: bool = False) -> PalmFrame:
    k = len(across)
    if k not in CLASS_NAMES:
        raise OnboardError(f"{kin.source}: found {k} non-thumb fingers; dgz names at most 4",
                           "check that the palm link is right (--palm-link)")
    classes = [""] * nf
    for name, i in zip(CLASS_NAMES[k], across):
        classes[i] = name
    if thumb is not None:
        classes[thumb] = "thumb"
    return PalmFrame(center, n, f, l, side, tuple(classes), margin, radial)
