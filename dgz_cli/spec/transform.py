"""Pure HandSpec transforms: what-if variants of a spec for evaluation (the simulated hand is not changed).

Imports nothing of dgz outside ``dgz_cli.spec``. Every transform returns a new frozen :class:`HandSpec`
and leaves its argument untouched.
"""

from __future__ import annotations

import math

from dgz_cli.spec.errors import SpecError
from dgz_cli.spec.models import HandSpec

# The physical features that are lengths (metres / FeatureNormalization.length). All others are not: see
# scale_lengths' docstring for the whole layout.
LENGTH_FEATURES: tuple[str, ...] = ("link_x", "link_y", "link_z")


def scale_lengths(spec: HandSpec, s: float) -> HandSpec:
    """``spec`` with every link length scaled by ``s`` *in its physical features only* (the URDF-prior
    sensitivity test of the paper's supplement: "scale every link length in the URDF by s, recompute the
    URDF-derived node features"; the policy, the simulated geometry and the protocol stay as they are).

    Which of the 27 per-node features (``spec.features.values[node]``, each value / scale, clipped to
    [-1, 1]; layout ``models.FEATURE_NAMES``) are lengths — what a uniform scaling of every link in the URDF
    changes when the features are recomputed:

    * ``link_x, link_y, link_z`` (3): the vector from the parent node's anchor to this node's anchor,
      palm frame, m / ``normalization.length``. **Scaled by s**, then clipped to [-1, 1] as onboarding clips.
    * ``limit_{FLEX,ABD,ROT}_{lo,hi}`` (6): joint ranges in primitive space, rad / π. Angles: not scaled.
      (They would be metres for a prismatic joint — a travel, not a link length; no shipped hand has one.
      Not scaled either.)
    * ``axis_{FLEX,ABD,ROT}_{x,y,z}`` (9): unit joint-axis directions. A uniform scaling keeps directions:
      not scaled.
    * ``vel_{FLEX,ABD,ROT}_{lo,hi}`` (6): joint speed bounds, rad/s. Not scaled.
    * ``damping_{FLEX,ABD,ROT}`` (3): joint damping, N·m·s/rad (a dynamics parameter, not a length).
      Not scaled.

    Everything else in the spec — node anchors, the palm frame and centre, M_h, limits, the mask — is read
    by the simulator or the joint mapping, not by the policy's physical-prior input, and is unchanged; so is
    the hand's name (results stay keyed by it). Inactive-primitive zeros stay zero; ``s == 1`` returns
    ``spec`` itself (bit-identical). Values are ``s · v`` (not re-rounded to onboarding's 6 decimals), so
    ``s = 2`` or ``1/4`` scale exactly.

    Raises :class:`SpecError` when ``s`` is not a finite number > 0, when the spec has no length features,
    or when ``s < 1`` meets a saturated length feature (|v| = 1: the link is at least
    ``normalization.length`` long and its true length, hence the scaled value, is unknown; re-onboard
    with a larger normalization instead).
    """
    if not (isinstance(s, (int, float)) and math.isfinite(s) and s > 0):
        raise SpecError(f"feature scale {s!r} must be a finite number > 0", "e.g. 2 or 0.25")
    if s == 1:
        return spec
    names = list(spec.features.names)
    missing = [n for n in LENGTH_FEATURES if n not in names]
    if missing:
        raise SpecError(f"hand '{spec.name}': its features have no {', '.join(missing)} column",
                        "re-onboard the hand with `dgz onboard` to get the 27-feature layout")
    cols = [names.index(n) for n in LENGTH_FEATURES]
    values: dict[str, list[float]] = {}
    for node, row in spec.features.values.items():
        new = list(row)
        for c in cols:
            if s < 1 and abs(row[c]) >= 1.0:
                raise SpecError(f"hand '{spec.name}', node '{node}': feature {names[c]} is saturated "
                                f"({row[c]}), so its value at scale {s} is unknown",
                                "use a scale ≥ 1, or re-onboard with a larger length normalization")
            new[c] = min(1.0, max(-1.0, s * row[c])) + 0.0  # + 0.0: no -0.0
        values[node] = new
    return spec.model_copy(update={"features": spec.features.model_copy(update={"values": values})})
