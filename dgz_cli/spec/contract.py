"""The control contract: what a policy observes and does, at which rates, over which episode.

This is the one home of those facts (design.md, "The control contract"). The simulator builds its
observations and applies actions through it, every checkpoint saves it, and ``dgz eval`` and
``dgz deploy`` read it back from the checkpoint, so a policy runs on hardware with the semantics it
was trained with. Nothing else declares a column offset, an action scale, a rate or a phase length.

Observation, batched over B graphs padded to N nodes (``nodes`` columns in ``ObservationLayout.node``
order, ``global`` columns in ``ObservationLayout.global_`` order):
    nodes      (B, N, node_dim)  float32
    global     (B, global_dim)   float32
    adjacency  (B, N, N)         float32   A[i, j] = 1 iff node i is the parent of node j
    physical   (B, N, 27)        float32   URDF-derived priors (HandSpec features)
    mask       (B, N, 3)         float32   activation mask (FLEX, ABD, ROT)
    node_valid (B, N)            bool      False on padding
Action (B, wrist_dim + n_prim·N), normalized to [-1, 1]: the wrist command (Δp along the palm axes
f, l, n; Δθ about them) then (FLEX, ABD, ROT) per node in ``spec.nodes`` order. One unit is
``wrist_scale`` (m or rad) on the wrist and ``finger_scale`` rad on a primitive.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

CONTRACT_VERSION = 1

# (name, width) blocks. The one-hots have one column per FINGER_CLASSES / NODE_TYPES entry of
# dgz_cli.spec.models (6 each).
NODE_BLOCKS: tuple[tuple[str, int], ...] = (
    ("d", 3),            # node → nearest object-surface point, palm frame, clipped to distance_clip, / distance_clip
    ("theta", 3),        # sign-corrected joint angle per primitive axis (mean over the node's joints), / π
    ("theta_dot", 3),    # the same for velocities, / velocity_scale, clipped to [-1, 1]
    ("contact", 1),      # contact flag (privileged: no supported hand measures it)
    ("force", 1),        # contact normal force / force_scale, clipped to [0, 5] (privileged)
    ("finger", 6),       # finger-class one-hot
    ("node_type", 6),    # node-type one-hot
)
GLOBAL_BLOCKS: tuple[tuple[str, int], ...] = (
    ("target", 3),       # palm centre → grasp target (object cloud centroid), palm frame, / target_scale
    ("v_wrist", 3),      # palm linear velocity, palm frame, m/s
    ("w_wrist", 3),      # palm angular velocity, palm frame, / 5 rad/s
    ("v_obj", 3),        # object linear velocity, palm frame, m/s (0 on hardware: static object)
    ("w_obj", 3),        # object angular velocity, palm frame, / 5 rad/s (0 on hardware)
    ("lift", 1),         # 1 after the grasp phase
)
# Optional blocks (the "markov" layout, issue 11): what makes the finger state Markov and the phase visible.
MARKOV_NODE_BLOCKS = NODE_BLOCKS + (
    ("pd_error", 3),     # (target − q) per primitive axis (sign-corrected mean), / pd_error_scale, clipped to [-1, 1]
)
MARKOV_GLOBAL_BLOCKS = GLOBAL_BLOCKS + (
    ("guide", 3),        # the wrist guidance error: target − grasp point, palm frame, / target_scale
    ("phase", 1),        # control step / episode_steps
)
PRIVILEGED_BLOCKS = frozenset({"contact", "force"})  # observed in simulation only


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


def _offsets(blocks: tuple[tuple[str, int], ...]) -> dict[str, slice]:
    out, start = {}, 0
    for name, width in blocks:
        out[name] = slice(start, start + width)
        start += width
    return out


class ObservationLayout(_Frozen):
    """Column blocks of the node and global feature arrays, and their fixed normalization scales."""

    node: tuple[tuple[str, int], ...] = NODE_BLOCKS
    global_: tuple[tuple[str, int], ...] = Field(GLOBAL_BLOCKS, alias="global")
    distance_clip: float = Field(0.3, gt=0, description="m: node → surface vectors are clipped to this norm and divided by it")
    force_scale: float = Field(10.0, gt=0, description="N: contact forces are observed as f / force_scale, clipped to [0, 5]")
    velocity_scale: float = Field(10.0, gt=0, description="rad/s: joint velocities are observed / this, clipped to [-1, 1]")
    target_scale: float = Field(0.5, gt=0, description="m: the grasp-target vector is observed / this, clipped to [-1, 1]")
    point_cloud: int = Field(256, ge=8, description="object surface points for the node → surface vectors")
    pd_error_scale: float = Field(0.1, gt=0, description="rad: the pd_error block is observed / this")

    model_config = ConfigDict(frozen=True, extra="forbid", populate_by_name=True)

    @field_validator("node", "global_")
    @classmethod
    def _blocks(cls, v: tuple[tuple[str, int], ...]) -> tuple[tuple[str, int], ...]:
        names = [n for n, _ in v]
        if len(set(names)) != len(names) or any(w <= 0 for _, w in v):
            raise ValueError("blocks need unique names and positive widths")
        return v

    @property
    def node_dim(self) -> int:
        return sum(w for _, w in self.node)

    @property
    def global_dim(self) -> int:
        return sum(w for _, w in self.global_)

    def node_col(self, name: str) -> slice:
        """Columns of node block ``name`` (KeyError if the layout has no such block)."""
        return _offsets(self.node)[name]

    def global_col(self, name: str) -> slice:
        return _offsets(self.global_)[name]

    def has(self, name: str) -> bool:
        return any(n == name for n, _ in self.node + self.global_)

    @property
    def privileged_inputs(self) -> tuple[str, ...]:
        """Blocks a real hand cannot provide (sorted)."""
        return tuple(sorted(PRIVILEGED_BLOCKS & {n for n, _ in self.node + self.global_}))


class WristGuidance(_Frozen):
    """Objective-driven wrist guidance (the paper's commented-out training detail; GraspXL steers its wrist
    the same way): during the grasp phase the wrist also moves by ``gain`` × (target − grasp point), at most
    ``speed_cap`` m per step, and the policy's wrist action is a residual on top. The target is the object
    cloud's centroid (on hardware: of the first perception frame), the grasp point the open hand's node
    centroid; orientation is held (no rotational guidance: the object is assumed static before the grasp,
    as on hardware, so holding the start orientation holds it in the object frame). ``gain`` 0 turns it off."""

    gain: float = Field(0.0, ge=0, le=1)
    speed_cap: float = Field(0.01, gt=0, le=0.1, description="m per control step")
    stop_gap: float | None = Field(None, gt=0, le=0.3, description="m: once the palm centre is within this of the "
                                   "nearest object-surface point (the wrist node's d), the guidance no longer moves "
                                   "the palm toward the object along its normal n (it still centres it in f and l); "
                                   "None = it presses on until the grasp point reaches the target")
    aim_residual: float | None = Field(None, gt=0, le=0.2, description="m per normalized unit: the policy's wrist "
                                       "translation action (after the residual gains and the clip) shifts the "
                                       "guidance's aim (the target, palm frame) by this instead of moving the wrist, "
                                       "so it sets an offset the palm keeps from a moving object rather than a "
                                       "velocity that drives the palm on; outside the grasp phase the translation "
                                       "dims do nothing. None = they move the wrist by wrist_scale per step")
    aim_axes: tuple[bool, bool, bool] = Field((True, True, True), description="the palm axes (f, l, n) whose "
                                              "translation action is an aim shift under aim_residual; the others "
                                              "stay velocities")

    def delta(self, target_m: np.ndarray, grasp_offset: np.ndarray, active: np.ndarray,
              palm_gap: np.ndarray | None = None, aim_shift: np.ndarray | None = None) -> np.ndarray:
        """(B, 6) wrist command (m, palm frame; zero rotation) from the palm → target vectors (B, 3) m and the
        palm → grasp-point offsets (B, 3) m, both in the palm frame; ``active`` (B,) bool; ``palm_gap`` (B,) m,
        palm centre → nearest surface point (needed when ``stop_gap`` is set); ``aim_shift`` (B, 3) m, palm
        frame, added to the target (see ``aim_residual``)."""
        aim = np.asarray(target_m, dtype=np.float64)
        if aim_shift is not None:
            aim = aim + np.asarray(aim_shift, dtype=np.float64)
        step = self.gain * (aim - np.asarray(grasp_offset))
        if self.stop_gap is not None:
            if palm_gap is None:
                raise ValueError("WristGuidance.stop_gap needs the palm gap")
            near = np.asarray(palm_gap)[..., None] < self.stop_gap
            step[..., 2:3] = np.where(near, np.minimum(step[..., 2:3], 0.0), step[..., 2:3])  # palm frame z = n
        norm = np.linalg.norm(step, axis=-1, keepdims=True)
        step = step * np.minimum(1.0, self.speed_cap / np.maximum(norm, 1e-12))
        out = np.zeros(step.shape[:-1] + (6,))
        out[..., :3] = step * np.asarray(active, dtype=float)[..., None]
        return out


class ClosingPrior(_Frozen):
    """A Markov prior the policy's action is a residual on (issue 11, lever 6): +FLEX (normalized 1) on every
    non-wrist node whose FLEX is active once the palm is within ``close_gap`` of the object surface or the
    episode reached ``close_step``, else 0; nothing on the wrist (the guidance approaches). It reads only the
    current observation (the wrist node's ``d``, the ``phase`` block), so the policy + prior stays Markov,
    unlike the scripted grasp's closing latch. Applied before the [-1, 1] clip, in sim and on hardware."""

    enabled: bool = False
    close_gap: float = Field(0.03, gt=0, le=0.3, description="m, palm centre to the nearest surface point")
    close_step: int = Field(50, ge=0, description="control step from which the prior closes regardless")
    close_guide: float | None = Field(None, gt=0, le=0.3, description="m: also close once the wrist guidance error "
                                      "(target − grasp point, the 'guide' block) is below this — the Markov form of the "
                                      "scripted grasp's stall test: at guidance gain g the approach slows below 2 mm "
                                      "per step at 0.002 / g m; None = off")


def check_translation_factors(v: float | tuple[float, ...] | None):
    """``v`` unchanged if every wrist translation factor in it lies in [0, 1], else ValueError."""
    factors = (v,) if isinstance(v, (int, float)) else (v or ())
    if any(not 0.0 <= f <= 1.0 for f in factors):
        raise ValueError(f"each translation factor must lie in [0, 1], got {v}")
    return v


class ActionLayout(_Frozen):
    wrist_dim: int = Field(6, gt=0)
    n_prim: int = Field(3, gt=0, description="primitives per node: FLEX, ABD, ROT")
    mode: Literal["primitive", "joint"] = Field(
        "primitive", description="'joint' (the paper's w/o-primitives ablation): a node's three values are raw "
                                 "increments of its actuated joints in M_h order, no sign")
    finger_scale: float = Field(0.015, gt=0, le=0.2, description="rad per unit of a finger action")
    wrist_scale: float = Field(0.01, gt=0, le=0.2, description="m or rad per unit of a wrist action")
    finger_max_lead: float | None = Field(None, gt=0, le=10, description="rad: a finger target stays within this "
                                          "of the measured joint (a blocked finger does not wind its target up); "
                                          "None = no cap")
    mask_actions: bool = Field(False, description="inactive primitive dimensions (activation mask 0) are not "
                               "actions: not sampled, not scored (log-prob, entropy, KL, BC)")
    wrist_residual: float = Field(1.0, ge=0, le=1, description="the policy's wrist action is multiplied by this "
                                  "before the prior and the guidance are added (0: the wrist follows the guidance "
                                  "and the lift alone)")
    finger_residual: float = Field(1.0, ge=0, le=1, description="the policy's finger actions are multiplied by this "
                                   "before the closing prior is added (< 1 bounds how far a residual can undo it)")
    wrist_translation_residual: float | tuple[float, float, float] | None = Field(
        None, description="factor on the policy's wrist translation actions alone (the first three wrist dims, palm "
                          "f/l/n), in [0, 1]: one for all three axes or one per axis (f, l, n); the rotation dims "
                          "keep wrist_residual. None = wrist_residual")

    @field_validator("wrist_translation_residual")
    @classmethod
    def _translation_in_unit_range(cls, v):
        return check_translation_factors(v)

    def dim(self, n_nodes: int) -> int:
        return self.wrist_dim + self.n_prim * n_nodes

    @property
    def translation_factors(self) -> tuple[float, float, float]:
        """The factors on the wrist's translation actions along the palm's (f, l, n) axes
        (``wrist_translation_residual``, else ``wrist_residual`` on all three)."""
        v = self.wrist_translation_residual
        if v is None:
            v = self.wrist_residual
        return (float(v),) * 3 if isinstance(v, (int, float)) else tuple(float(f) for f in v)

    @property
    def scales_residual(self) -> bool:
        """Whether :meth:`residual_gains` differ from 1 anywhere."""
        return (self.wrist_residual != 1.0 or any(f != 1.0 for f in self.translation_factors)
                or self.finger_residual != 1.0)

    @property
    def wrist_is_action(self) -> bool:
        """Whether the wrist dims are actions (sampled and scored): always, unless ``mask_actions`` and a
        ``wrist_residual`` of 0 (translation included) leave them without effect."""
        return not (self.mask_actions and self.wrist_residual == 0 and not any(self.translation_factors))

    def residual_gains(self, n_nodes: int) -> np.ndarray:
        """(wrist_dim + n_prim·N,) the factors on the policy's own normalized action (all 1 by default): the
        wrist's translation dims (the first three, palm f/l/n) × :attr:`translation_factors`, its rotation dims ×
        ``wrist_residual``, the finger dims × ``finger_residual``."""
        wrist = np.full(self.wrist_dim, self.wrist_residual)
        wrist[:3] = self.translation_factors
        return np.concatenate([wrist, np.full(self.n_prim * n_nodes, self.finger_residual)])

    def scales(self, n_nodes: int) -> np.ndarray:
        """(wrist_dim + n_prim·N,) physical units of one normalized action unit."""
        return np.concatenate([np.full(self.wrist_dim, self.wrist_scale), np.full(self.n_prim * n_nodes, self.finger_scale)])


class EpisodeProtocol(_Frozen):
    """Rates and phases. The policy acts at every control step of every phase; during ``lift`` the wrist
    is also raised by ``lift_height / lift_steps`` per step along world +z; success needs the object
    ≥ success_fraction × lift_height above its start through the hold."""

    physics_dt: float = Field(0.0025, gt=0, le=0.05, description="s (400 Hz)")
    control_hz: float = Field(20.0, gt=0, le=1000)
    grasp_steps: int = Field(120, ge=1)
    lift_steps: int = Field(30, ge=0)
    hold_s: float = Field(2.0, ge=0)
    lift_height: float = Field(0.5, gt=0, le=2.0, description="m")
    success_fraction: float = Field(0.8, ge=0, le=1.0)

    @property
    def substeps(self) -> int:
        return int(round(1.0 / (self.control_hz * self.physics_dt)))

    @property
    def hold_steps(self) -> int:
        return int(round(self.hold_s * self.control_hz))

    @property
    def episode_steps(self) -> int:
        return self.grasp_steps + self.lift_steps + self.hold_steps

    def phase(self, k: int) -> Literal["grasp", "lift", "hold"]:
        """Phase of control step k (0-based)."""
        if k < self.grasp_steps:
            return "grasp"
        return "lift" if k < self.grasp_steps + self.lift_steps else "hold"

    def lift_per_step(self) -> float:
        return self.lift_height / max(1, self.lift_steps)

    @model_validator(mode="after")
    def _rates(self) -> "EpisodeProtocol":
        ratio = 1.0 / (self.control_hz * self.physics_dt)
        if abs(ratio - round(ratio)) > 1e-6 or round(ratio) < 1:
            raise ValueError(f"the control period must be a whole number of physics steps "
                             f"(1 / (control_hz · physics_dt) = {ratio:.4g})")
        return self


class StartPose(_Frozen):
    """The hand's joint pose when an episode starts: the pose every simulated episode resets to and the pose
    ``dgz deploy`` ramps the real hand to before the policy's first step (then the hand file's ``start_pose``
    entries). Every joint is at its rest value (0 clipped into its limits: the flat open hand), except the
    thumb's opening joints: the joints of ``finger == "thumb"`` nodes whose primitive is in ``thumb_primitives``
    move ``thumb_open`` of the way from rest to the limit in their + direction (design.md: +ABD opens the thumb
    away from the index, +ROT turns its pad toward the fingers). ``thumb_open`` 1 with ABD is the paper's
    pre-grasp (Supp. S2: "setting its thumb-opening DoF to the maximum opening angle for each hand")."""

    thumb_open: float = Field(0.0, ge=0, le=1, description="fraction of the thumb's opening range (0 = the rest "
                                                            "pose, as every policy before issue 11's E11 was trained)")
    thumb_primitives: tuple[Literal["ABD", "ROT"], ...] = Field(("ABD",), min_length=1)

    def pose(self, spec) -> np.ndarray:
        """(L,) joint values in ``spec.joints`` order for a HandSpec ``spec``."""
        q = spec.rest_pose()  # the one definition of the rest pose (spec.models.rest_pose)
        if self.thumb_open == 0.0:
            return q
        thumb = {n.id for n in spec.nodes if n.finger == "thumb"}
        for i, r in enumerate(spec.joints):
            if r.node in thumb and r.primitive.value in self.thumb_primitives:
                q[i] += self.thumb_open * ((r.upper if r.sign > 0 else r.lower) - q[i])
        return q


class ControlContract(_Frozen):
    """Observation layout + action layout + episode protocol, versioned; saved in every checkpoint."""

    version: Literal[1] = CONTRACT_VERSION
    observation: ObservationLayout = ObservationLayout()
    action: ActionLayout = ActionLayout()
    episode: EpisodeProtocol = EpisodeProtocol()
    guidance: WristGuidance = WristGuidance()
    prior: ClosingPrior = ClosingPrior()
    start: StartPose = StartPose()

    @model_validator(mode="after")
    def _prior_needs_phase(self) -> "ControlContract":
        if self.prior.enabled and not self.observation.has("phase"):
            raise ValueError("the closing prior reads the 'phase' block: use an observation layout that has it")
        if self.prior.enabled and self.prior.close_guide is not None and not self.observation.has("guide"):
            raise ValueError("prior.close_guide reads the 'guide' block: use an observation layout that has it")
        if self.guidance.aim_residual is not None and self.guidance.gain == 0.0:
            raise ValueError("guidance.aim_residual shifts the guidance's aim: it needs guidance.gain > 0")
        if self.guidance.stop_gap is not None and self.guidance.stop_gap >= self.observation.distance_clip:
            raise ValueError(f"guidance.stop_gap {self.guidance.stop_gap} m must be below the observation's "
                             f"distance_clip {self.observation.distance_clip} m (the palm gap is read from d)")
        return self

    def action_units(self) -> tuple[tuple[str, ...], np.ndarray, float]:
        """What one unit of the policy's own action commands before the [-1, 1] clip: (kinds (wrist_dim,),
        amounts (wrist_dim,), finger amount). A wrist dim is an ``"aim"`` shift of the guidance's target (m, a
        translation dim on an ``aim_axes`` axis under ``guidance.aim_residual``) or a ``"velocity"`` (m or rad
        per control step); the finger amount is in rad per step. Two contracts whose kinds agree command the same
        thing from actions that differ by the ratio of the amounts (up to the clip)."""
        act, aim = self.action, self.guidance.aim_residual
        kinds = ["velocity"] * act.wrist_dim
        amounts = np.full(act.wrist_dim, act.wrist_residual * act.wrist_scale)
        for i, factor in enumerate(act.translation_factors):
            on_aim = aim is not None and self.guidance.aim_axes[i]
            kinds[i] = "aim" if on_aim else "velocity"
            amounts[i] = factor * (aim if on_aim else act.wrist_scale)
        return tuple(kinds), amounts, act.finger_residual * act.finger_scale

    def wrist_nodes(self, nodes: np.ndarray, node_valid: np.ndarray) -> np.ndarray:
        """(B, N) bool: the valid nodes whose ``node_type`` block marks the wrist, in an observation's nodes
        (B, N, node_dim) and node_valid (B, N)."""
        from dgz_cli.spec.models import NODE_TYPES

        wrist_col = self.observation.node_col("node_type").start + NODE_TYPES.index("wrist")
        return (np.asarray(nodes)[..., wrist_col] > 0) & np.asarray(node_valid, bool)

    def palm_gap(self, nodes: np.ndarray, node_valid: np.ndarray) -> np.ndarray:
        """(B,) m, palm centre → nearest object-surface point: the norm of the wrist node's ``d`` block in the
        observation's nodes (B, N, node_dim), node_valid (B, N); inf for a graph without a wrist node."""
        lay = self.observation
        d = np.asarray(nodes)[..., lay.node_col("d")].astype(np.float64) * lay.distance_clip
        return np.where(self.wrist_nodes(nodes, node_valid), np.linalg.norm(d, axis=-1), np.inf).min(-1)

    def wrist_command(self, wrist_action: np.ndarray, glob: np.ndarray, grasp_offset: np.ndarray, active: np.ndarray,
                      nodes: np.ndarray | None = None, node_valid: np.ndarray | None = None) -> np.ndarray:
        """(B, 6) the wrist command (m and rad, palm frame; the lift comes on top) from the composed and clipped
        wrist action (B, wrist_dim) and the observation: the action × ``wrist_scale`` plus
        :meth:`guidance_action`; with ``guidance.aim_residual`` the translation dims shift the guidance's aim
        instead of moving the wrist (on the ``guidance.aim_axes``). The simulator and the deploy loop both call this."""
        a = np.asarray(wrist_action, dtype=np.float64)
        out = a * self.action.wrist_scale
        shift = None
        if self.guidance.aim_residual is not None:
            axes = np.asarray(self.guidance.aim_axes, dtype=bool)
            shift = a[:, :3] * self.guidance.aim_residual * axes
            out[:, :3] = np.where(axes, 0.0, out[:, :3])
        return out + self.guidance_action(glob, grasp_offset, active, nodes, node_valid, aim_shift=shift)

    def guidance_action(self, glob: np.ndarray, grasp_offset: np.ndarray, active: np.ndarray,
                        nodes: np.ndarray | None = None, node_valid: np.ndarray | None = None,
                        aim_shift: np.ndarray | None = None) -> np.ndarray:
        """(B, 6) the wrist guidance from observations' global features (B, global_dim): the target block
        decoded to metres (shifted by ``aim_shift`` (B, 3) m if given), then :meth:`WristGuidance.delta`; zeros
        when the guidance is off. With ``guidance.stop_gap`` it also reads the palm gap from the nodes
        (B, N, node_dim) and node_valid (B, N). The simulator and the deploy loop both call this, on the
        observation the policy sees."""
        if self.guidance.gain == 0.0:
            return np.zeros(np.shape(glob)[:1] + (6,))
        lay = self.observation
        target = np.asarray(glob)[:, lay.global_col("target")].astype(np.float64) * lay.target_scale
        gap = None
        if self.guidance.stop_gap is not None:
            if nodes is None or node_valid is None:
                raise ValueError("guidance.stop_gap reads the palm gap: pass the observation's nodes and node_valid")
            gap = self.palm_gap(nodes, node_valid)
        return self.guidance.delta(target, grasp_offset, active, gap, aim_shift)

    def compose(self, policy_action: np.ndarray, nodes: np.ndarray, glob: np.ndarray, closing: np.ndarray,
                node_valid: np.ndarray) -> np.ndarray:
        """(B, action_dim) the normalized command before the [-1, 1] clip: the policy's action (B, action_dim)
        times :meth:`ActionLayout.residual_gains`, plus :meth:`prior_action` of the same observation. The
        simulator and the deploy loop both call this."""
        a = np.asarray(policy_action, dtype=np.float64)
        n = node_valid.shape[1]
        if self.action.scales_residual:
            a = a * self.action.residual_gains(n)
        if self.prior.enabled:
            a = a + self.prior_action(nodes, glob, closing, node_valid)
        return a

    def prior_action(self, nodes: np.ndarray, glob: np.ndarray, closing: np.ndarray, node_valid: np.ndarray) -> np.ndarray:
        """(B, action_dim) the closing prior's normalized action (zeros when disabled) from an observation:
        nodes (B, N, node_dim), global (B, global_dim), node_valid (B, N), and the hand's static ``closing``
        (B, N, n_prim): the direction each node action closes the hand (``sim.scene.static_graph``: +1 on
        FLEX in the primitive mode, each FLEX joint's sign in its slot in the joint mode)."""
        act, lay = self.action, self.observation
        b, n = node_valid.shape
        out = np.zeros((b, act.dim(n)))
        if not self.prior.enabled:
            return out
        is_wrist = self.wrist_nodes(nodes, node_valid)
        gap = self.palm_gap(nodes, node_valid)
        step = np.rint(glob[:, lay.global_col("phase")].astype(np.float64)[:, 0] * self.episode.episode_steps)
        close = (gap < self.prior.close_gap) | (step >= self.prior.close_step)
        if self.prior.close_guide is not None:
            guide = glob[:, lay.global_col("guide")].astype(np.float64) * lay.target_scale
            close |= np.linalg.norm(guide, axis=-1) < self.prior.close_guide
        on = node_valid & ~is_wrist & close[:, None]
        out[:, act.wrist_dim:] = (np.asarray(closing, dtype=np.float64) * on[..., None]).reshape(b, -1)
        return out

    @property
    def privileged_inputs(self) -> tuple[str, ...]:
        return self.observation.privileged_inputs


def finger_targets(targets: np.ndarray, alpha: np.ndarray, joint_node: np.ndarray, joint_prim: np.ndarray,
                   joint_sign: np.ndarray, joint_slot: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                   action: ActionLayout, step_cap: np.ndarray | float = math.inf,
                   q: np.ndarray | None = None) -> np.ndarray:
    """New joint targets from per-node finger actions, the one mapping sim and runtime share.

    targets (B, L) rad; alpha (B, N, n_prim) normalized finger actions (already clipped to [-1, 1]);
    joint_node / joint_prim / joint_slot (B, L) int, joint_sign (B, L) ±1 (0 on padded joints);
    lower / upper (B, L) rad. Each joint moves by sign · α[node, primitive] · finger_scale (or, in
    ``joint`` mode, α[node, slot] · finger_scale), by at most ``step_cap`` rad, stays within
    ``action.finger_max_lead`` of the measured joints ``q`` (B, L) when given, and stays in its limits.
    Returns (B, L).
    """
    b = np.arange(targets.shape[0])[:, None]
    if action.mode == "primitive":
        dq = joint_sign * alpha[b, joint_node, joint_prim] * action.finger_scale
    else:
        dq = alpha[b, joint_node, joint_slot] * action.finger_scale * (joint_sign != 0)
    dq = np.clip(dq, -step_cap, step_cap)
    new = targets + dq
    if q is not None and action.finger_max_lead is not None:
        lead = action.finger_max_lead
        # as for the wrist: a command may not grow the lead beyond the cap, but a lead that is already
        # larger (the joint was pushed) is not yanked back
        bound = np.maximum(lead, np.abs(targets - q))
        new = np.clip(new, q - bound, q + bound)
    return np.clip(new, lower, upper)
