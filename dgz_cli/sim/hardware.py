"""The grasping env under a :class:`~dgz_cli.spec.hardware_view.HardwareView`: the observation a real hand
and camera give (noisy joint readings, the object cloud of the first frame held), and optionally the
teacher's privileged observation of the same state alongside (for distillation).

:class:`HardwareViewEnv` is a :class:`~dgz_cli.sim.env.GraspEnv` whose ``reset``/``step``/``advance`` return
the perturbed observation, in the env config's layout (a student's: no privileged blocks). The env's wrist
guidance and closing prior read the observation it returned, so under ``held_cloud`` they use the held
centroid, as the deploy loop does on hardware. Rewards and success use the true state.

With ``teacher_layout`` (a layout that adds ``contact``/``force`` to the env's), :attr:`teacher_obs` holds
the unperturbed observation of the same state in that layout after every reset and step; with
``teacher_sees_view`` it holds the perturbed one (the student's observation) plus the contact and force blocks,
for a teacher trained under the same view.

Randomness: the noise of slot b in its e-th episode comes from ``default_rng([seed, b, e, 1])``, so one slot
sees the same noise in ``dgz eval`` and on ``dgz deploy --hand sim`` (one slot), whatever the batch.
"""

from __future__ import annotations

import numpy as np

from dgz_cli.sim import observe
from dgz_cli.sim.env import GraspEnv
from dgz_cli.spec.contract import ObservationLayout
from dgz_cli.spec.hardware_view import HardwareView

_PRIV_LAYOUT = ObservationLayout(node=(("contact", 1), ("force", 1), ("finger", 6), ("node_type", 6)))


class HardwareViewEnv(GraspEnv):
    def __init__(self, pairs, cfg, view: HardwareView, *, teacher_layout: ObservationLayout | None = None,
                 teacher_sees_view: bool = False, **kwargs) -> None:
        self.view, self.teacher_layout, self.teacher_sees_view = view, teacher_layout, teacher_sees_view
        self.teacher_obs: dict[str, np.ndarray] | None = None
        super().__init__(pairs, cfg, **kwargs)
        B, L = self.B, self.L
        self._fresh = np.ones(B, bool)  # slots whose next observation is their episode's first
        self._held_pos, self._held_rot = np.zeros((B, 3)), np.tile(np.eye(3), (B, 1, 1))
        self._noise = np.zeros((B, L))   # the joint-reading noise of the last observation, rad
        self._qd_err = np.zeros((B, L))  # its finite difference, rad/s
        self._rngs: list[np.random.Generator | None] = [None] * B
        self._priv_layout = _PRIV_LAYOUT.model_copy(update=dict(force_scale=cfg.contract.observation.force_scale))
        if teacher_layout is not None:
            own = {n for n, _ in cfg.contract.observation.node + cfg.contract.observation.global_}
            missing = {n for n, _ in teacher_layout.node + teacher_layout.global_} - own - {"contact", "force"}
            if missing:
                raise ValueError(f"the teacher's layout has blocks {sorted(missing)} the env's layout lacks")

    def _reset_slot(self, b: int) -> None:
        super()._reset_slot(b)
        self._fresh[b] = True

    def _observe(self):
        obs, d_world, obj_z = super()._observe()
        # An env step observes every slot once, then (if some finished and were reset) again for those:
        # the second pass only updates the fresh slots (the env keeps only their rows of it).
        rows = np.flatnonzero(self._fresh) if self._fresh.any() else np.arange(self.B)
        seen = self._perturb(obs, rows) if self.view.active else obs
        if self.teacher_layout is not None:
            self._teacher(seen if self.teacher_sees_view else obs, rows)
        self._fresh[:] = False
        return seen, d_world, obj_z

    # ---------------------------------------------------------------- the teacher's observation
    def _teacher(self, obs: dict, rows: np.ndarray) -> None:
        """The observation ``obs`` (unperturbed, or the student's) in ``teacher_layout``: the env's blocks plus
        contact and force."""
        lay, tl = self.cfg.contract.observation, self.teacher_layout
        force = self.buf["force"]
        priv = observe.node_features(self._priv_layout, self.node_valid, self.static_nodes, contact=force > 1e-6,
                                     force=force)
        nodes = np.empty(obs["nodes"].shape[:2] + (tl.node_dim,), np.float32)
        for name, _ in tl.node:
            src = priv[..., self._priv_layout.node_col(name)] if name in ("contact", "force") else \
                obs["nodes"][..., lay.node_col(name)]
            nodes[..., tl.node_col(name)] = src
        glob = np.empty((self.B, tl.global_dim), np.float32)
        for name, _ in tl.global_:
            glob[:, tl.global_col(name)] = obs["global"][:, lay.global_col(name)]
        if self.teacher_obs is None or len(rows) == self.B:
            self.teacher_obs = {**{k: v for k, v in obs.items() if k not in ("nodes", "global")},
                                "nodes": nodes, "global": glob}
        else:
            self.teacher_obs = dict(self.teacher_obs)
            self.teacher_obs["nodes"] = self.teacher_obs["nodes"].copy()
            self.teacher_obs["global"] = self.teacher_obs["global"].copy()
            self.teacher_obs["nodes"][rows] = nodes[rows]
            self.teacher_obs["global"][rows] = glob[rows]

    # ---------------------------------------------------------------- the hardware view
    def _perturb(self, obs: dict, rows: np.ndarray) -> dict:
        view, lay, ep = self.view, self.cfg.contract.observation, self.cfg.contract.episode
        B, N = self.B, self.N
        fresh = np.flatnonzero(self._fresh)
        xpos, xmat = self.buf["xpos"], self.buf["xmat"].reshape(B, N + 2, 3, 3)
        for b in fresh:  # the first frame of an episode: take the cloud, start the noise stream
            self._held_pos[b], self._held_rot[b] = xpos[b, N], xmat[b, N]
            self._rngs[b] = np.random.default_rng([self.seed, int(b), int(self.episodes[b]), 1])
        nodes_w, palm_pos, palm_rot = self._frames()
        q, qd = self.buf["q"], self.buf["qd"][:, :self.L]
        if view.joint_noise > 0:
            for b in rows:
                new = self._rngs[b].normal(0.0, view.joint_noise, self.L) * self.joint_valid[b]
                # the velocity error is the noise's finite difference (none at the first frame)
                step = np.zeros(self.L) if self._fresh[b] else new - self._noise[b]
                self._noise[b], self._qd_err[b] = new, step * ep.control_hz
            q = q + self._noise
            qd = qd + self._qd_err
        node_blocks: dict[str, np.ndarray] = {}
        glob_blocks: dict[str, np.ndarray] = {}
        if view.held_cloud:
            d = observe.nearest_surface(nodes_w, self._held_pos, self._held_rot, self.cloud, self.cloud_pre)
            d *= self.node_valid[..., None]
            node_blocks["d"] = observe.to_frame(d, palm_rot)
            center = self.grasp_target(self._held_pos, self._held_rot)
            target = observe.to_frame(center - palm_pos, palm_rot)
            glob_blocks.update(target=target, v_obj=np.zeros((B, 3)), w_obj=np.zeros((B, 3)))
            if lay.has("guide"):
                glob_blocks["guide"] = (target - self.grasp_offset) / lay.target_scale
        if view.joint_noise > 0:
            node_blocks.update(theta=observe.primitive_state(q, self.proj),
                               theta_dot=observe.primitive_state(qd, self.proj))
            if lay.has("pd_error"):
                node_blocks["pd_error"] = observe.pd_error(self.targets, q, self.proj, lay.pd_error_scale)
        nodes, glob = obs["nodes"].copy(), obs["global"].copy()
        node_blocks = {k: v for k, v in node_blocks.items() if lay.has(k)}
        glob_blocks = {k: v for k, v in glob_blocks.items() if lay.has(k)}
        if node_blocks:
            sub = ObservationLayout(node=tuple((k, lay.node_col(k).stop - lay.node_col(k).start) for k in node_blocks)
                                    + (("finger", 6), ("node_type", 6)), distance_clip=lay.distance_clip,
                                    velocity_scale=lay.velocity_scale, pd_error_scale=lay.pd_error_scale)
            x = observe.node_features(sub, self.node_valid, self.static_nodes, **node_blocks)
            for k in node_blocks:
                nodes[rows, :, lay.node_col(k)] = x[rows][..., sub.node_col(k)]
        if glob_blocks:
            sub = ObservationLayout(node=(("finger", 6), ("node_type", 6)),
                                    global_=tuple((k, lay.global_col(k).stop - lay.global_col(k).start)
                                                  for k in glob_blocks), target_scale=lay.target_scale)
            g = observe.global_features(sub, **glob_blocks)
            for k in glob_blocks:
                glob[rows, lay.global_col(k)] = g[rows][:, sub.global_col(k)]
        return {**obs, "nodes": nodes, "global": glob}
