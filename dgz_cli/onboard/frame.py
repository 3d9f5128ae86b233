"""Palm frame, thumb detection, finger classes and side, estimated from the kinematics.

Rules (documented in docs/onboarding.md):
- curl_i: at the rest pose, the direction fingertip i moves when its last joint closes
  (closing = towards the wider side of that joint's range; a digit's last joint always curls).
- Thumb: the finger whose curl agrees least with the others (lowest mean cosine); none if
  every finger curls alike (mean cosine > 0.9 for all).
- a: the mean closing axis of the non-thumb fingers' last joints; f: from the palm centre
  (centroid of the palm's collision geometry) towards the non-thumb fingertips, orthogonal to
  a; n = a × f (the side the fingers curl to); l = n × f. Palm frame axes: x = f, y = l, z = n.
- Side: right when the thumb base lies on the −l side of the other finger bases.
- Classes across the palm from the thumb side: 4 fingers index..little, 3 index..ring,
  2 middle/ring, 1 middle (Barrett = thumb/middle/ring, as in the paper).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgz_cli.onboard.compile import Poser
from dgz_cli.onboard.structure import Structure
from dgz_cli.onboard.urdf import Kinematics
from dgz_cli.spec.errors import OnboardError
from dgz_cli.spec.kinematics import rest_pose

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


def estimate(kin: Kinematics, poser: Poser, st: Structure) -> PalmFrame:
    poser.pose(poser.rest())
    tips = tip_positions(poser, st)
    bases = np.array([poser.joint_anchor(c.joints[0]) for c in st.chains])
    curls = []
    for c, t in zip(st.chains, tips):
        last = c.joints[-1]
        axis = poser.joint_axis(last) * closing_sign(kin, last)
        v = np.cross(axis, t - poser.joint_anchor(last)) if kin.joints[last].type != "prismatic" else axis
        curls.append(_unit(v))
    curls = np.array(curls)
    nf = len(st.chains)

    thumb, margin = None, 1.0
    if nf >= 3:
        cos = curls @ curls.T
        agree = (cos.sum(1) - 1.0) / (nf - 1)
        order = np.argsort(agree)
        if agree[order[0]] < 0.9:
            thumb = int(order[0])
            margin = float(agree[order[1]] - agree[order[0]])
    others = [i for i in range(nf) if i != thumb]

    pts = poser.geom_points(list(st.palm_group))
    center = pts.mean(0) if len(pts) else poser.link_pos(st.palm_link)
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
    k = len(others)
    if k not in CLASS_NAMES:
        raise OnboardError(f"{kin.source}: found {k} non-thumb fingers; dgz names at most 4",
                           "check that the palm link is right (--palm-link)")
    across = sorted(others, key=lambda i: (bases[i] @ l) * (1 if side == "right" else -1))
    classes = [""] * nf
    for name, i in zip(CLASS_NAMES[k], across):
        classes[i] = name
    if thumb is not None:
        classes[thumb] = "thumb"
    return PalmFrame(center, n, f, l, side, tuple(classes), margin)
