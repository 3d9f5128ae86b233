"""HandSpec: the one contract between onboarding, simulation, policy and hardware.

Frozen pydantic models with ``extra="forbid"``; written as YAML by :mod:`dgz_cli.spec.io`.
All vectors are expressed in the palm frame (x = f finger axis, y = l = n × f, z = n palm
normal) unless the field says otherwise; lengths in metres, angles in radians.
"""

from __future__ import annotations

from enum import Enum
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator


SCHEMA_VERSION = 1
PRIMITIVES = ("FLEX", "ABD", "ROT")
FINGER_CLASSES = ("thumb", "index", "middle", "ring", "little", "wrist")
NODE_TYPES = ("wrist", "metacarpal", "proximal", "middle", "distal", "fingertip")
FEATURE_NAMES = (
    [f"limit_{p}_{b}" for p in PRIMITIVES for b in ("lo", "hi")]
    + [f"axis_{p}_{c}" for p in PRIMITIVES for c in "xyz"]
    + [f"vel_{p}_{b}" for p in PRIMITIVES for b in ("lo", "hi")]
    + [f"damping_{p}" for p in PRIMITIVES]
    + [f"link_{c}" for c in "xyz"]
)
N_FEATURES = len(FEATURE_NAMES)  # 27

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


def rest_pose(lower, upper) -> np.ndarray:
    """Rest pose (L,) for joint limits ``lower``, ``upper`` (L,): 0 clipped into [lower, upper] (the flat open
    hand on the shipped hands). The one definition; onboarding, the sim, hw and the runtime use it."""
    return np.clip(0.0, np.asarray(lower, dtype=float), np.asarray(upper, dtype=float))


class Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class Primitive(str, Enum):
    FLEX = "FLEX"
    ABD = "ABD"
    ROT = "ROT"


class Excitation(Frozen):
    """Settings of the unit-joint excitation that identified M_h (Supp. S1-B)."""

    delta: float = Field(description="excitation step, rad (m for prismatic joints)")
    flexed_fraction: float = Field(description="fraction of the closing range used for the flexed re-excitation")
    margin_threshold: float = Field(description="decisions with a smaller margin are flagged")


class Provenance(Frozen):
    urdf: str = Field(description="source URDF/xacro path, relative to the asset root when under it")
    urdf_sha256: str = Field(pattern=r"^[0-9a-f]{64}$")
    upstream: str | None = None
    upstream_commit: str | None = None
    xacro_args: dict[str, str] = Field(default_factory=dict)
    dgz_version: str
    excitation: Excitation


class Palm(Frozen):
    """Palm frame. ``normal``/``finger_axis``/``lateral`` are unit vectors in the palm *link* frame."""

    link: str
    normal: Vec3 = Field(description="n: out of the palm, the side the fingers close toward")
    finger_axis: Vec3 = Field(description="f: wrist → finger bases, orthogonal to n")
    lateral: Vec3 = Field(description="l = n × f")
    center: Vec3 = Field(description="palm centre (centroid of its collision geometry), palm link frame")
    side: Literal["left", "right"]


class Node(Frozen):
    id: str
    finger: Literal["thumb", "index", "middle", "ring", "little", "wrist"]
    type: Literal["wrist", "metacarpal", "proximal", "middle", "distal", "fingertip"]
    parent: str | None
    joints: list[str] = Field(default_factory=list, max_length=3, description="member joints (actuated or mimic)")
    anchor_link: str
    anchor_point: Vec3 = Field(description="anchor in anchor_link's frame (first joint's position; tip point)")


class JointMap(Frozen):
    """One row of M_h: Δq_joint = sign · α[node, primitive]."""

    joint: str
    node: str
    primitive: Primitive
    sign: Literal[-1, 1]
    lower: float
    upper: float
    velocity: float
    effort: float
    damping: float
    margin: float = Field(ge=0.0, le=1.0, description="best − second-best excitation score")
    flagged: bool = Field(description="ambiguous decision: check it, override it if wrong")
    source: Literal["identified", "override"] = "identified"
    identified_primitive: Primitive | None = Field(default=None, description="set when an override changed the row")
    identified_sign: Literal[-1, 1] | None = None

    @field_validator("lower", "upper", "velocity", "effort", "damping")
    @classmethod
    def _finite(cls, v: float) -> float:
        if v != v or v in (float("inf"), float("-inf")):
            raise ValueError("must be finite")
        return v


class MimicJoint(Frozen):
    joint: str
    source: str
    multiplier: float
    offset: float
    node: str | None


class FeatureNormalization(Frozen):
    """Physical features are value / scale, clipped to [-1, 1]."""

    limit: float = Field(gt=0, description="rad (m for prismatic) per unit")
    velocity: float = Field(gt=0, description="rad/s per unit")
    damping: float = Field(gt=0, description="N·m·s/rad per unit")
    length: float = Field(gt=0, description="m per unit")
    default_velocity: float = Field(gt=0, description="used where the URDF gives velocity ≤ 0")


class Features(Frozen):
    names: list[str]
    normalization: FeatureNormalization
    values: dict[str, list[float]] = Field(description="node id → 27 normalized numbers")


class JointOverride(Frozen):
    node: str | None = None
    primitive: Primitive | None = None
    sign: Literal[-1, 1] | None = None
    reason: str = Field(min_length=3, description="why the identified value is wrong")


class Overrides(Frozen):
    """Human decisions, kept apart from what was identified so a re-onboard never loses them."""

    joints: dict[str, JointOverride] = Field(default_factory=dict)
    command_order: list[str] | None = Field(default=None, description="actuated joints in the robot's command order")
    command_order_reason: str | None = None
    upstream: str | None = None
    upstream_commit: str | None = None


class HandSpec(Frozen):
    schema_version: Literal[1] = SCHEMA_VERSION
    name: str = Field(pattern=r"^[a-z0-9][a-z0-9_\-]*$")
    provenance: Provenance
    palm: Palm
    nodes: list[Node]
    joints: list[JointMap] = Field(description="M_h for every actuated joint, in command order")
    mimic: list[MimicJoint] = Field(default_factory=list)
    excluded_joints: list[str] = Field(default_factory=list, description="movable joints above the palm (an arm)")
    activation_mask: dict[str, list[int]] = Field(description="node id → [FLEX, ABD, ROT] ∈ {0,1}")
    features: Features
    overrides: Overrides = Field(default_factory=Overrides)

    def rest_pose(self) -> np.ndarray:
        """(L,) rest pose in ``joints`` order: every joint at 0 clipped into its limits (the flat open hand)."""
        return rest_pose([r.lower for r in self.joints], [r.upper for r in self.joints])

    def node_index(self) -> dict[str, int]:
        return {n.id: i for i, n in enumerate(self.nodes)}

    def derived_mask(self) -> dict[str, list[int]]:
        """The activation mask implied by M_h (paper Sec. III-C-2)."""
        mask = {n.id: [0, 0, 0] for n in self.nodes}
        for row in self.joints:
            if row.node in mask:
                mask[row.node][PRIMITIVES.index(row.primitive.value)] = 1
        return mask
