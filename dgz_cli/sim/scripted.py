"""A scripted grasp controller that uses only the HandSpec (through the env's observation).

Approach along the palm normal (steering the object centre under the open hand's node centroid), stop when the palm centre
(the wrist node's anchor) is ``standoff`` from the object surface, touches it, or stops getting closer for 3 steps,
then close with +FLEX on every
node; the env's lift phase lifts the wrist. It proves the env and the signs end to end and is the
floor a learned policy must beat.
"""

from __future__ import annotations

import numpy as np

from dgz_cli.spec.contract import ControlContract
from dgz_cli.spec.models import NODE_TYPES


class ScriptedGrasp:
    def __init__(self, n_nodes: int, grasp_offset: np.ndarray, contract: ControlContract = ControlContract(),
                 standoff: float = 0.03) -> None:
        """``grasp_offset`` (B, 3): palm centre → the open hand's node centroid, palm frame; the
        controller steers the object centre under it (f, l) while approaching along n. It reads the
        observation through ``contract``'s layout and acts in its action layout."""
        self.n_nodes, self.offset, self.standoff = n_nodes, grasp_offset, standoff
        self.contract = contract
        lay = contract.observation
        self.clip, self.target_scale = lay.distance_clip, lay.target_scale
        self.col_d = lay.node_col("d").start
        self.col_wrist = lay.node_col("node_type").start + NODE_TYPES.index("wrist")
        self.col_contact = lay.node_col("contact").start if lay.has("contact") else None
        self.target = lay.global_col("target")
        self.closing: np.ndarray | None = None
        self.last_gap: np.ndarray | None = None
        self.stalled: np.ndarray | None = None

    @classmethod
    def for_env(cls, env) -> ScriptedGrasp:
        """The scripted grasp for every slot of GraspEnv ``env``, under the env's control contract (the policy
        factory of `dgz eval --policy scripted` and the warm-start teacher of `dgz train`)."""
        return cls(env.N, env.grasp_offset, env.cfg.contract)

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Forget the phase of the slots in ``mask`` (all when None)."""
        if self.closing is not None:
            if mask is None:
                self.closing[:] = False
                self.last_gap[:] = np.inf
                self.stalled[:] = 0
            else:
                self.closing[mask] = False
                self.last_gap[mask] = np.inf
                self.stalled[mask] = 0

    def act(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(B, 6 + 3N) primitive action from the observation dict of :class:`GraspEnv`."""
        nodes, glob, valid = obs["nodes"], obs["global"], obs["node_valid"]
        b = nodes.shape[0]
        if self.closing is None:
            self.closing = np.zeros(b, bool)
            self.last_gap = np.full(b, np.inf)
            self.stalled = np.zeros(b, dtype=np.int64)
        wrist_node = np.argmax(nodes[:, :, self.col_wrist] * valid, axis=1)
        palm_gap = np.linalg.norm(nodes[np.arange(b), wrist_node, self.col_d:self.col_d + 3], axis=-1) * self.clip
        palm_touch = (nodes[np.arange(b), wrist_node, self.col_contact] > 0 if self.col_contact is not None
                      else np.zeros(b, bool))
        # the palm stopped getting closer for 3 steps: something is in the way (a heavy arm only accelerates slowly)
        self.stalled = np.where(self.last_gap - palm_gap < 0.002, self.stalled + 1, 0)
        self.closing |= (palm_gap < self.standoff) | palm_touch | (self.stalled >= 3)
        self.last_gap = palm_gap
        act = self.contract.action
        action = np.zeros((b, act.dim(self.n_nodes)), dtype=np.float32)
        error = glob[:, self.target] * self.target_scale - self.offset  # object centre relative to the grasp point, m
        approach = np.stack([error[:, 0] * 20.0, error[:, 1] * 20.0, np.ones(b)], axis=1)
        if self.contract.guidance.gain == 0.0:  # with guidance on, the contract's guidance approaches
            action[:, :3] = np.where(self.closing[:, None], 0.0, np.clip(approach, -1, 1))
        flex = np.zeros((b, self.n_nodes, act.n_prim), dtype=np.float32)
        is_wrist = nodes[:, :, self.col_wrist] > 0  # wrist flexion would tilt the palm away
        flex[:, :, 0] = obs["mask"][:, :, 0] * ~is_wrist
        action[:, act.wrist_dim:] = np.where(self.closing[:, None], flex.reshape(b, -1), 0.0)
        return action
