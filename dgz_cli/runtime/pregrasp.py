"""The start pose with the thumb pre-opened (paper Supp. S2: "the thumb starts with maximum opening
distance"), derived from the HandSpec alone: no per-hand code.

For every joint of a thumb node (``finger == "thumb"``), in ``spec.joints`` order:

* FLEX joints go to the limit that moves the primitive in the −FLEX direction (+FLEX closes on every
  hand, design.md): the upper limit when ``sign < 0``, the lower limit when ``sign > 0``.
* ABD and ROT joints: their sign convention (+ABD away from the index, +ROT toward opposition) does not
  say whether the tip moves away from the *other fingertips* (on the Inspire and Revo2 the thumb's
  "ABD" is the opposition swing). So forward kinematics decides: each joint takes the limit (or keeps its
  rest value) that maximizes the mean distance from the thumb tip to the other fingertips, given the
  joints already set; a limit must gain at least 1 mm to be taken.

Every other joint stays at its rest value (0 clipped into the limits: the flat open hand). The runtime
clips the result to the narrower of spec and device limits before ramping to it.
"""

from __future__ import annotations

import numpy as np

from dgz_cli.spec.kinematics import HandKinematics
from dgz_cli.runtime.mapping import start_pose
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec

MIN_GAIN = 1e-3  # m


def thumb_spread(kin: HandKinematics, q: np.ndarray) -> float | None:
    """Mean distance (m) from the thumb tip to the other fingertips at joint values ``q`` (L,)."""
    tips = kin.fingertips(q)
    thumb = tips.pop("thumb", None)
    if thumb is None or not tips:
        return None
    return float(np.mean([np.linalg.norm(thumb - p) for p in tips.values()]))


def thumb_open_pose(spec: HandSpec, kin: HandKinematics | None = None) -> np.ndarray:
    """(L,) rest pose with the thumb opened as described above; without ``kin`` only FLEX is opened."""
    lo = np.array([r.lower for r in spec.joints], dtype=float)
    hi = np.array([r.upper for r in spec.joints], dtype=float)
    q = spec.rest_pose()
    thumb = {n.id for n in spec.nodes if n.finger == "thumb"}
    rows = [(i, r) for i, r in enumerate(spec.joints) if r.node in thumb]
    for i, r in rows:
        if r.primitive.value == "FLEX":
            q[i] = hi[i] if r.sign < 0 else lo[i]
    if kin is None:
        return q
    for i, r in rows:
        if r.primitive.value == "FLEX":
            continue
        best = thumb_spread(kin, q)
        if best is None:
            break
        keep = q[i]
        for candidate in (lo[i], hi[i]):
            q[i] = candidate
            spread = thumb_spread(kin, q)
            if spread is not None and spread > best + MIN_GAIN:
                best, keep = spread, candidate
        q[i] = keep
    return q


def deploy_start_pose(spec: HandSpec, overrides: dict[str, float] | None = None,
                      asset_root: str | None = None) -> tuple[np.ndarray, str | None]:
    """(L,) start pose (thumb open, then the hand file's ``start_pose`` entries) and a warning or None.

    Without the hand's URDF (vendor assets not found) only the thumb's FLEX joints are opened.
    """
    try:
        kin: HandKinematics | None = HandKinematics.for_spec(spec, asset_root)
        note = None
    except DgzError as exc:
        kin = None
        note = (f"thumb ABD/ROT joints stay at rest (no forward kinematics: {exc.message}); "
                "set --asset-root or DGZ_ASSET_ROOT to open the thumb fully")
    return start_pose(spec, overrides, base=thumb_open_pose(spec, kin)), note
