"""HandSpec: the one contract between onboarding, simulation, policy and hardware.

Frozen pydantic models with ``extra="forbid"``; written as YAML by :mod:`dgz_cli.spec.io`.
All vectors are expressed in the palm frame (x = f finger axis, y = l = n × f, z = n palm
normal) unless the field says otherwise; lengths in metres, angles in radians.
"""

from __future__ import annotations

from enum import Enum
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator, model_validator
from pydantic_core import PydanticCustomError


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

Coord = Annotated[float, Field(allow_inf_nan=False, ge=-1e3, le=1e3)]  # finite, bounded (m, or unit vectors)
Vec3 = Annotated[list[Coord], Field(min_length=3, max_length=3)]


def _bad(message: str) -> PydanticCustomError:
    """A validation error whose text is ``message`` as written (no "Value error, " prefix)."""
    return PydanticCustomError("handspec", message)


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

    @field_validator("normal", "finger_axis", "lateral")
    @classmethod
    def _unit(cls, v: list[float]) -> list[float]:
        norm = float(np.linalg.norm(v))
        if not abs(norm - 1.0) <= 1e-2:
            raise _bad(f"must be a unit vector (its length is {norm:.4g}); re-run `dgz onboard` or fix the palm frame")
        return v


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

    @model_validator(mode="after")
    def _ordered(self) -> "JointMap":
        if self.lower > self.upper:
            raise _bad(f"joint '{self.joint}': lower {self.lower} > upper {self.upper} (swap the limits)")
        return self


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

    # Cross-references are checked on load, so every consumer (lint, scene, sim, hw, runtime) sees a spec whose
    # names resolve: no KeyError anywhere downstream. Deeper consistency (mask = M_h, tree shape, the URDF) is lint's.
    @field_validator("nodes")
    @classmethod
    def _node_ids(cls, nodes: list[Node]) -> list[Node]:
        ids = [n.id for n in nodes]
        for k, n in enumerate(nodes):
            if ids.index(n.id) != k:
                raise _bad(f"nodes[{k}].id: node id '{n.id}' is used more than once")
            if n.parent is not None and n.parent not in ids:
                raise _bad(f"nodes[{k}].parent: node '{n.id}' has unknown parent '{n.parent}'")
        return nodes

    @field_validator("joints")
    @classmethod
    def _rows(cls, rows: list[JointMap], info: ValidationInfo) -> list[JointMap]:
        ids = {n.id for n in info.data.get("nodes") or []}
        names = [r.joint for r in rows]
        for k, r in enumerate(rows):
            if names.index(r.joint) != k:
                raise _bad(f"joints[{k}].joint: joint '{r.joint}' appears more than once in M_h")
            if "nodes" in info.data and r.node not in ids:
                raise _bad(f"joints[{k}].node: M_h row '{r.joint}' names unknown node '{r.node}'")
        return rows

    @field_validator("mimic")
    @classmethod
    def _mimic(cls, mimic: list[MimicJoint], info: ValidationInfo) -> list[MimicJoint]:
        names = {r.joint for r in info.data.get("joints") or []}
        ids = {n.id for n in info.data.get("nodes") or []}
        for k, m in enumerate(mimic):
            if "joints" in info.data and m.source not in names:
                raise _bad(f"mimic[{k}].source: mimic joint '{m.joint}' follows '{m.source}', which is not in M_h")
            if "nodes" in info.data and m.node is not None and m.node not in ids:
                raise _bad(f"mimic[{k}].node: mimic joint '{m.joint}' names unknown node '{m.node}'")
        return mimic

    @field_validator("activation_mask")
    @classmethod
    def _mask(cls, mask: dict[str, list[int]], info: ValidationInfo) -> dict[str, list[int]]:
        ids = {n.id for n in info.data.get("nodes") or []}
        for nid, row in mask.items():
            if "nodes" in info.data and nid not in ids:
                raise _bad(f"activation_mask.{nid}: mask row for unknown node '{nid}'")
            if len(row) != 3 or any(b not in (0, 1) for b in row):
                raise _bad(f"activation_mask.{nid}: {row} is not three 0/1 flags [FLEX, ABD, ROT]")
        return mask

    @field_validator("overrides")
    @classmethod
    def _command_order(cls, ov: Overrides, info: ValidationInfo) -> Overrides:
        names = [r.joint for r in info.data.get("joints") or []]
        if ov.command_order is not None and "joints" in info.data:
            unknown = [j for j in ov.command_order if j not in names]
            if unknown:
                raise _bad(f"overrides.command_order: '{unknown[0]}' is not an actuated joint of this spec "
                           f"(M_h joints: {', '.join(names[:8])}{', ...' if len(names) > 8 else ''})")
        return ov

    def rest_pose(self) -> np.ndarray:
        """(L,) rest pose in ``joints`` order: every joint at 0 clipped into its limits (the flat open hand)."""
        return rest_pose([r.lower for r in self.joints], [r.upper for r in self.joints])

    def node_index(self) -> dict[str, int]:
        return {n.id: i for i, n in enumerate(self.nodes)}

    def joint_slots(self) -> np.ndarray:
        """(L,) each actuated joint's position among its node's joints, in ``joints`` order (the value of a
        node's action that drives it in the joint action mode)."""
        seen: dict[str, int] = {}
        slots = np.zeros(len(self.joints), dtype=np.int64)
        for j, row in enumerate(self.joints):
            slots[j] = seen.get(row.node, 0)
            seen[row.node] = slots[j] + 1
        return slots

    def derived_mask(self) -> dict[str, list[int]]:
        """The activation mask implied by M_h (paper Sec. III-C-2)."""
        mask = {n.id: [0, 0, 0] for n in self.nodes}
        for row in self.joints:
            if row.node in mask:
                mask[row.node][PRIMITIVES.index(row.primitive.value)] = 1
        return mask
