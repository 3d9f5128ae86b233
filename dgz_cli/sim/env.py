"""Batched grasping environment over many (hand, object) slots, hands mixed in one batch.

API (Gymnasium-style naming, arrays batched over B slots, padded to N nodes and L joints):
    obs = env.reset(seed)                            # dict of arrays, see ``observation``
    obs, reward, terminated, truncated, info = env.step(action)
Observation and action layouts, scales, rates and phases are the control contract
(``cfg.contract``, :mod:`dgz_cli.spec.contract`); the finger mapping is the contract's
:func:`~dgz_cli.spec.contract.finger_targets`, shared with the deploy runtime. Wrist Δp is along the palm
frame f/l/n, Δθ increments the wrist hinges about the palm's f, l, n axes. Episodes: ``grasp_steps``
policy steps, then ``lift_steps`` during which the wrist is also lifted by ``lift_height``, then
``hold_steps`` holding. A slot that finishes is reset at once; its final statistics are in
``info["episode"]`` and its last observation (before the reset) in ``info["final_obs"]``.
Gymnasium semantics: ``terminated`` marks a true terminal state (none in this task yet), ``truncated``
the time limit or a MuJoCo instability (that slot alone is reset, and counted).
"""

from __future__ import annotations

import copy
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from dgz_cli.sim import observe
from dgz_cli.sim.gather import BatchGather
from dgz_cli.sim.objects import ObjectModel
from dgz_cli.sim.reward import GRASPXL_TERMS, TERMS, graspxl_terms, graspxl_total, reward_terms, total
from dgz_cli.sim.scene import build_scene, static_graph
from dgz_cli.sim.slot import Slot, contact_table
from dgz_cli.spec.contract import finger_targets
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.models import NODE_TYPES, HandSpec


class GraspEnv:
    def __init__(self, pairs: list[tuple[HandSpec, ObjectModel]], cfg: EnvConfig = EnvConfig(), seed: int = 0,
                 asset_root: str | None = None, threads: int = 2, use_pen: bool = True) -> None:
        self.cfg, self.use_pen, self.seed = cfg, use_pen, seed
        cache: dict[tuple[str, str], tuple] = {}
        self.slots: list[Slot] = []
        model_of = []
        for spec, obj in pairs:
            key = (spec.name, obj.name)
            if key not in cache:
                model, index, _ = build_scene(spec, obj, cfg, asset_root, seed)
                cache[key] = (model, index, contact_table(model, index), len(cache))
            model, index, pair_node, m = cache[key]
            if cfg.dynamics_noise > 0:  # each slot's dynamics are drawn per episode: it needs its own model
                model = copy.copy(model)
            self.slots.append(Slot(spec, obj, model, index, cfg, pair_node))  # else slots share the (hand, object) model
            model_of.append(m)
        self.B = len(self.slots)
        self.N = max(len(s.spec.nodes) for s in self.slots)
        self.L = max(s.n_joints for s in self.slots)
        self._static()
        self.pool = ThreadPoolExecutor(max_workers=threads) if threads > 1 else None
        self.chunks = [list(range(self.B))[k::threads] for k in range(max(1, threads))]
        self.instabilities = 0
        self.timing = {"physics_s": 0.0, "env_other_s": 0.0}  # wall-clock split of step(), accumulated
        self.t = np.zeros(self.B, dtype=np.int64)
        self.episodes = np.zeros(self.B, dtype=np.int64)
        self.targets = np.zeros((self.B, self.L))
        self._dq = np.zeros((self.B, self.L))  # the last step's applied joint change and primitive actions (rewards)
        self._alpha = np.zeros((self.B, self.N, self.cfg.contract.action.n_prim))
        self._residual_sq = np.zeros(self.B)  # the last step's mean squared policy action (r_residual)
        self.wrist_target = np.zeros((self.B, 6))
        self.target_shift = np.zeros((self.B, 3))  # world m, per episode (EnvConfig.target_noise)
        self.prev_palm = np.zeros((self.B, 3))
        self.prev_rot = np.tile(np.eye(3), (self.B, 1, 1))
        self.ok_hold = np.ones(self.B, bool)
        self.ret = np.zeros(self.B)
        self.max_rise = np.zeros(self.B)
        self.touched = np.zeros(self.B, bool)        # any hand-object contact so far in the episode
        self.max_push = np.zeros(self.B)            # largest object displacement during the grasp phase, m
        self.rise_lift_end = np.zeros(self.B)       # the object's rise at the end of the lift phase, m
        self.terms = GRASPXL_TERMS if cfg.reward_variant == "graspxl" else TERMS
        self.term_sums = {k: np.zeros(self.B) for k in self.terms}
        B, N, L = self.B, self.N, self.L
        self.buf = dict(xpos=np.zeros((B, N + 2, 3)), xmat=np.tile(np.eye(3).reshape(9), (B, N + 2, 1)),
                        q=np.zeros((B, L)), qd=np.zeros((B, L + 6)), force=np.zeros((B, N)), wq=np.zeros((B, 6)))
        self.gather = BatchGather(self.slots, self.buf, [v[2] for v in cache.values()], model_of)
        self.palm_axes = np.stack([s.idx.palm_axes for s in self.slots])
        self.palm_center = np.stack([s.idx.palm_center for s in self.slots])
        self.grasp_offset = np.stack([s.idx.grasp_offset for s in self.slots])  # (B, 3) palm frame
        self.z0 = np.zeros(B)  # settled object heights, set at each slot's reset
        self._palm_velocity = np.zeros((B, 3))  # world, m/s, at the last observation
        self.p0 = np.zeros((B, 3))  # settled object positions (the push limit)
        self._global = np.zeros((B, cfg.contract.observation.global_dim), np.float32)  # the last observation's
        self._nodes = np.zeros((B, self.N, cfg.contract.observation.node_dim), np.float32)
        tip = NODE_TYPES.index("fingertip")
        self.node_weight = self.node_valid * np.where(self.node_type[..., tip] > 0, cfg.graspxl.tip_weight, 1.0)

    # ---------------------------------------------------------------- static padded arrays
    def _static(self) -> None:
        B, N, L = self.B, self.N, self.L
        self.node_valid = np.zeros((B, N), bool)
        self.joint_valid = np.zeros((B, L), bool)
        self.adjacency = np.zeros((B, N, N), np.float32)
        self.physical = np.zeros((B, N, 27), np.float32)
        self.mask = np.zeros((B, N, 3), np.float32)
        self.closing = np.zeros((B, N, 3), np.float32)  # each node action's closing direction (static_graph)
        self.finger = np.zeros((B, N, 6))
        self.node_type = np.zeros((B, N, 6))
        self.joint_node = np.zeros((B, L), np.int64)
        self.joint_prim = np.zeros((B, L), np.int64)
        self.joint_sign = np.zeros((B, L))
        self.joint_slot = np.zeros((B, L), np.int64)
        self.limits = np.zeros((B, L, 2))
        self.proj = np.zeros((B, 3 * N, L))
        self.node_point = np.zeros((B, N, 3))
        self.cloud = np.zeros((B, self.cfg.contract.observation.point_cloud, 3))
        for b, s in enumerate(self.slots):
            g = static_graph(s.spec, self.cfg.contract.action.mode)
            n, l = len(s.spec.nodes), s.n_joints
            self.node_valid[b, :n] = True
            self.joint_valid[b, :l] = True
            self.adjacency[b, :n, :n] = g["adjacency"]
            self.physical[b, :n] = g["physical"]
            self.mask[b, :n] = g["mask"]
            self.finger[b, :n] = g["finger"]
            self.node_type[b, :n] = g["node_type"]
            self.joint_node[b, :l], self.joint_prim[b, :l], self.joint_sign[b, :l] = \
                g["joint_node"], g["joint_prim"], g["joint_sign"]
            self.limits[b, :l] = s.idx.limits
            self.joint_slot[b, :l] = g["joint_slot"]
            self.closing[b, :n] = g["closing"]
            self.proj[b, :3 * n, :l] = observe.projection(g["joint_node"], g["joint_prim"], g["joint_sign"], n)
            self.node_point[b, :n] = s.idx.node_point
            self.cloud[b] = s.idx.cloud
        wrist_dim = self.cfg.contract.action.wrist_dim
        # (B, action_dim) 1 on the wrist and on the mask-enabled primitives of real nodes (r_residual's dims)
        wrist_acts = float(self.cfg.contract.action.wrist_is_action)
        self._active_dims = np.concatenate([np.full((B, wrist_dim), wrist_acts), (
            (self.mask > 0) & self.node_valid[..., None]).reshape(B, -1)], axis=1).astype(np.float64)
        self.cloud_pre = observe.cloud_terms(self.cloud)  # constants of observe.nearest_surface
        self.cloud_sum = self.cloud.sum(axis=1)  # (B, 3), for cloud_centroid
        self.static_nodes = observe.static_features(self.finger, self.node_type, self.node_valid)

    def cloud_centroid(self, obj_pos: np.ndarray, obj_rot: np.ndarray) -> np.ndarray:
        """(B, 3) world: the object cloud's centroid for object poses ``obj_pos`` (B, 3), ``obj_rot`` (B, 3, 3):
        R · Σp / P, the same up to rounding as averaging the rotated points."""
        return obj_pos + np.einsum("bij,bj->bi", obj_rot, self.cloud_sum) / self.cloud.shape[1]

    def grasp_target(self, obj_pos: np.ndarray, obj_rot: np.ndarray) -> np.ndarray:
        """(B, 3) world: the grasp target the observation reports and the guidance steers to, the cloud's
        centroid plus this episode's ``target_shift`` (0 unless ``target_noise``)."""
        return self.cloud_centroid(obj_pos, obj_rot) + self.target_shift

    def state(self) -> dict[str, np.ndarray]:
        """The raw quantities the observation is built from, batched (copies; for tests and debugging):
        ``nodes`` (B, N, 3) node anchors, ``palm_pos`` (B, 3) / ``palm_rot`` (B, 3, 3) palm centre and
        frame (f, l, n columns), ``obj_pos`` (B, 3), ``obj_rot`` (B, 3, 3), ``obj_vel`` (B, 6) (free joint
        velocities), ``q`` / ``qd`` (B, L), ``wq`` (B, 6), ``force`` (B, N) contact normal force per node (N)."""
        B, N, L, buf = self.B, self.N, self.L, self.buf
        xmat = buf["xmat"].reshape(B, N + 2, 3, 3)
        nodes, palm_pos, palm_rot = self._frames()
        return dict(
            nodes=nodes, palm_rot=palm_rot, palm_pos=palm_pos,
            obj_pos=buf["xpos"][:, N].copy(), obj_rot=xmat[:, N].copy(), obj_vel=buf["qd"][:, L:].copy(),
            q=buf["q"].copy(), qd=buf["qd"][:, :L].copy(), wq=buf["wq"].copy(), force=buf["force"].copy())

    def _frames(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """From the batch buffers: node anchors (B, N, 3), palm centre (B, 3) and palm frame (B, 3, 3;
        columns f, l, n), world frame."""
        B, N, buf = self.B, self.N, self.buf
        xpos, xmat = buf["xpos"], buf["xmat"].reshape(B, N + 2, 3, 3)
        palm_link_rot = xmat[:, N + 1]
        palm_pos = xpos[:, N + 1] + np.einsum("bij,bj->bi", palm_link_rot, self.palm_center)
        return observe.node_positions(xpos[:, :N], xmat[:, :N], self.node_point), palm_pos, palm_link_rot @ self.palm_axes

    @property
    def pair_names(self) -> list[str]:
        """'hand/object' of every slot (B,), the key of episode records' hand and object."""
        return [f"{s.spec.name}/{s.obj.name}" for s in self.slots]

    @property
    def action_dim(self) -> int:
        return self.cfg.contract.action.dim(self.N)

    # ---------------------------------------------------------------- reset
    def reset(self, seed: int | None = None) -> dict[str, np.ndarray]:
        if seed is not None:
            self.seed = seed
        self.episodes[:] = 0
        for b in range(self.B):
            self._reset_slot(b)
        obs = self._observe()[0]
        self._global, self._nodes = obs["global"], obs["nodes"]
        return obs

    def _reset_slot(self, b: int) -> None:
        rng = np.random.default_rng([self.seed, b, int(self.episodes[b])])
        self.episodes[b] += 1
        s = self.slots[b]
        if self.cfg.dynamics_noise > 0:  # its own stream, so the start state's draws are the same either way
            r = self.cfg.dynamics_noise
            s.set_dynamics(*np.exp(np.random.default_rng([self.seed, b, int(self.episodes[b]), 1]).uniform(-r, r, 3)))
        s.reset(rng)
        if self.cfg.target_noise > 0:  # drawn after the slot's own draws, so the start state is the same either way
            self.target_shift[b, :2] = rng.normal(0.0, self.cfg.target_noise, 2)
        self.targets[b] = 0.0
        self.targets[b, :s.n_joints] = s.idx.start_q
        self.wrist_target[b] = s.wrist_q0
        self.t[b] = 0
        self.ok_hold[b] = True
        self.ret[b] = 0.0
        self.max_rise[b] = 0.0
        self.touched[b] = False
        self.max_push[b] = 0.0
        self.rise_lift_end[b] = 0.0
        for v in self.term_sums.values():
            v[b] = 0.0
        s.gather()
        self.gather.assemble(slice(b, b + 1))
        self.z0[b] = s.z0
        self.p0[b] = self.buf["xpos"][b, self.N]
        rot = self.buf["xmat"][b, self.N + 1].reshape(3, 3)
        self.prev_rot[b] = rot @ self.palm_axes[b]
        self.prev_palm[b] = self.buf["xpos"][b, self.N + 1] + rot @ self.palm_center[b]

    # ---------------------------------------------------------------- step
    def step(self, action: np.ndarray):
        """action (B, action_dim) normalized → (obs, reward (B,), terminated (B,), truncated (B,), info)."""
        t_start = time.perf_counter()
        self.apply_action(action)
        return self.advance(t_start)

    def apply_action(self, action: np.ndarray) -> None:
        """Turn normalized actions (B, action_dim) into joint and wrist targets through the contract:
        clip to [-1, 1], fingers by :func:`finger_targets`, wrist by ``wrist_scale`` plus the protocol's lift."""
        cfg, B = self.cfg, self.B
        act, ep = cfg.contract.action, cfg.contract.episode
        a = np.nan_to_num(np.asarray(action, dtype=np.float64))
        self._residual_sq = (np.clip(a, -1.0, 1.0) ** 2 * self._active_dims).sum(-1) / np.maximum(self._active_dims.sum(-1), 1.0)
        # the policy's action is a (scaled) residual on the contract's Markov prior
        a = np.clip(cfg.contract.compose(a, self._nodes, self._global, self.closing, self.node_valid), -1.0, 1.0)
        wrist, fingers = a[:, :act.wrist_dim], a[:, act.wrist_dim:]
        alpha = fingers.reshape(B, self.N, act.n_prim) * self.node_valid[..., None]
        new_targets = finger_targets(self.targets, alpha, self.joint_node, self.joint_prim, self.joint_sign,
                                     self.joint_slot, self.limits[..., 0], self.limits[..., 1], act, q=self.buf["q"])
        self.set_targets(new_targets, alpha if act.mode == "primitive" else np.zeros_like(alpha))
        c = cfg.contract
        self.move_wrist(c.wrist_command(wrist, self._global, self.grasp_offset, self.t < ep.grasp_steps, self._nodes,
                                        self.node_valid), self.lifting() * ep.lift_per_step())

    def guidance(self, glob: np.ndarray, nodes: np.ndarray) -> np.ndarray:
        """(B, 6) the contract's wrist guidance from an observation's global (B, global_dim) and node
        (B, N, node_dim) features, without a ``guidance.aim_residual`` shift (that needs the action:
        ``ControlContract.wrist_command``, which :meth:`apply_action` and the deploy runtime call)."""
        c = self.cfg.contract
        return c.guidance_action(glob, self.grasp_offset, self.t < c.episode.grasp_steps, nodes, self.node_valid)

    def set_targets(self, targets: np.ndarray, alpha: np.ndarray | None = None) -> None:
        """New finger joint targets (B, L) rad for the next step; ``alpha`` (B, N, n_prim) the normalized
        primitive actions behind them (for r_pen; zeros if None)."""
        self._dq = (targets - self.targets) * self.joint_valid
        self._alpha = np.zeros((self.B, self.N, self.cfg.contract.action.n_prim)) if alpha is None else alpha
        self.targets = targets

    def advance(self, t_start: float | None = None):
        """One control period of physics with the targets set since the last call, then the observation,
        reward and episode bookkeeping; returns what :meth:`step` returns."""
        t_start = time.perf_counter() if t_start is None else t_start
        cfg, B, ep = self.cfg, self.B, self.cfg.contract.episode
        dq, alpha = self._dq, self._alpha
        t_phys = time.perf_counter()
        ok = self._physics()
        physics = time.perf_counter() - t_phys
        self.timing["physics_s"] += physics
        self.t += 1
        force = self.buf["force"].copy()
        contact = force > 1e-6
        obs, d_world, obj_z = self._observe()
        rise = obj_z - self.z0
        self.max_rise = np.maximum(self.max_rise, rise)
        self.touched |= contact.any(-1)
        in_grasp = self.t <= ep.grasp_steps
        disp = np.linalg.norm(self.buf["xpos"][:, self.N] - self.p0, axis=-1)
        self.max_push = np.where(in_grasp, np.maximum(self.max_push, disp), self.max_push)
        self.rise_lift_end = np.where(self.t == ep.grasp_steps + ep.lift_steps, rise, self.rise_lift_end)
        risen = rise >= ep.success_fraction * ep.lift_height
        holding = self.t > ep.grasp_steps + ep.lift_steps
        self.ok_hold &= np.where(holding, risen, True)
        done = self.t >= ep.episode_steps
        success = done & self.ok_hold & (risen if ep.hold_steps == 0 else True)
        pushed = np.zeros(B, bool)
        if cfg.reward_variant == "graspxl":
            obj_vel = self.buf["qd"][:, self.L:self.L + 3]
            pushed = in_grasp & (disp > cfg.graspxl.push_limit)
            palm_v = self._palm_velocity * (self.t > ep.grasp_steps)[:, None]
            terms = graspxl_terms(d_world, contact, force / cfg.contract.observation.force_scale, self.node_weight,
                                  obj_vel - palm_v, rise, self.t > ep.grasp_steps, success, pushed, ep.lift_height,
                                  residual_sq=self._residual_sq, displacement=disp,
                                  push_limit=cfg.graspxl.push_limit)
            reward = graspxl_total(terms, cfg.graspxl)
        else:
            terms = reward_terms(d_world, contact, force / cfg.contract.observation.force_scale, dq, alpha, self.mask,
                                 self.node_valid, cfg.force_threshold, rise=rise, lifting=self.t > ep.grasp_steps,
                                 lift_height=ep.lift_height)
            reward = total(terms, cfg.reward, self.use_pen)
        reward[~ok] = 0.0
        self.ret += reward
        for k in self.terms:
            self.term_sums[k] += terms[k]
        push_end = pushed & ok & ~done
        terminated = push_end.copy()
        if cfg.early_stop:  # training only: an episode that can no longer succeed ends here (a true terminal state)
            hopeless = ((self.t >= ep.grasp_steps) & ~self.touched) | ~self.ok_hold
            terminated |= hopeless & ok & ~done
        info = {"reward_terms": terms, "unstable": ~ok, "success": success, "episode": {}}
        finished = np.nonzero(done | ~ok | terminated)[0]
        for b in finished:
            info["episode"][int(b)] = dict(success=bool(success[b]), unstable=not ok[b], pushed=bool(push_end[b]),
                                           return_=float(self.ret[b]),
                                           steps=int(self.t[b]), max_rise=float(self.max_rise[b]), touched=bool(self.touched[b]),
                                           max_push=float(self.max_push[b]), rise_lift_end=float(self.rise_lift_end[b]),
                                           hand=self.slots[b].spec.name,
                                           object=self.slots[b].obj.name,
                                           **{f"r_{k}": float(self.term_sums[k][b] / max(1, self.t[b])) for k in self.terms})
            self.instabilities += int(not ok[b])
            self._reset_slot(int(b))
        if len(finished):
            info["final_obs"] = {k: v.copy() for k, v in obs.items() if k in ("nodes", "global")}
            fresh = self._observe()[0]
            for key in ("nodes", "global"):
                obs[key][finished] = fresh[key][finished]
        self.timing["env_other_s"] += time.perf_counter() - t_start - physics
        self._global, self._nodes = obs["global"], obs["nodes"]
        return obs, reward.astype(np.float32), terminated, (done | ~ok) & ~terminated, info

    def lifting(self) -> np.ndarray:
        """(B,) bool: the slots whose next step is in the lift phase."""
        ep = self.cfg.contract.episode
        return (self.t >= ep.grasp_steps) & (self.t < ep.grasp_steps + ep.lift_steps)

    def move_wrist(self, command: np.ndarray, lift: np.ndarray) -> None:
        """Integrate the wrist targets: ``command`` (B, 6) physical (Δp along the palm axes at the last
        observation, Δθ about them), then ``lift`` (B,) m along world +z (the protocol's lift, not capped)."""
        palm_rot = self.prev_rot  # palm frame at the last observation
        dp_world = np.einsum("bij,bj->bi", palm_rot, command[:, :3])
        # the wrist slides move along the world axes; its hinges turn about the palm's f, l, n axes
        delta = np.concatenate([dp_world, command[:, 3:]], axis=1)
        # A blocked wrist must not wind its target up (it would press with ever growing force), and a
        # pushed wrist must not drag its target along: commands may not grow the lead beyond the max.
        wq = self.buf["wq"]
        bound = np.maximum(self.cfg.wrist_max_lead, np.abs(self.wrist_target - wq))
        self.wrist_target = np.clip(self.wrist_target + delta, wq - bound, wq + bound)
        self.wrist_target[:, 2] += lift

    def _physics(self) -> np.ndarray:
        """Step every slot one control period on the worker threads (MuJoCo releases the GIL); each slot
        copies its raw state right after its step, overlapping the other thread's physics. Then the
        batch buffers are picked from those copies, vectorized. Returns the per-slot stability flags."""
        ctrl = np.concatenate([self.wrist_target, self.targets], axis=1)
        ok = np.ones(self.B, bool)
        slots = self.slots

        def run(chunk: list[int]) -> None:
            for b in chunk:
                s = slots[b]
                ok[b] = s.advance(ctrl[b, :6 + s.n_joints])
                s.gather()

        if self.pool is None:
            run(list(range(self.B)))
        else:
            list(self.pool.map(run, self.chunks))
        self.gather.assemble(slice(0, self.B))
        return ok & np.isfinite(self.gather.raw["qpos"]).all(axis=1)  # NaN anywhere in the slot's qpos

    # ---------------------------------------------------------------- observation
    def _observe(self):
        """Observation from the batch buffers; returns (obs, node→surface world vectors, object z)."""
        cfg, buf = self.cfg, self.buf
        layout, ep = cfg.contract.observation, cfg.contract.episode
        force = buf["force"]
        B, N, L = self.B, self.N, self.L
        xpos, xmat = buf["xpos"], buf["xmat"].reshape(B, N + 2, 3, 3)
        q, qd = buf["q"], buf["qd"][:, :L]
        obj_pos, obj_rot, obj_vel = xpos[:, N], xmat[:, N], buf["qd"][:, L:]
        nodes, palm_pos, palm_rot = self._frames()
        d_world = observe.nearest_surface(nodes, obj_pos, obj_rot, self.cloud, self.cloud_pre)
        d_world *= self.node_valid[..., None]
        dt = 1.0 / ep.control_hz
        v_w = (palm_pos - self.prev_palm) / dt
        w_w = observe.rotation_delta(self.prev_rot, palm_rot) / dt
        self.prev_palm, self.prev_rot = palm_pos, palm_rot
        center = self.grasp_target(obj_pos, obj_rot)
        self._palm_velocity = v_w
        target = observe.to_frame(center - palm_pos, palm_rot)
        extra_g, extra_n = {}, {}
        if layout.has("guide"):
            extra_g["guide"] = (target - self.grasp_offset) / layout.target_scale
        if layout.has("phase"):
            extra_g["phase"] = self.t / ep.episode_steps
        if layout.has("pd_error"):
            extra_n["pd_error"] = observe.pd_error(self.targets, q, self.proj, layout.pd_error_scale)
        glob = observe.global_features(
            layout, target=target, v_wrist=observe.to_frame(v_w, palm_rot),
            w_wrist=observe.to_frame(w_w, palm_rot), v_obj=observe.to_frame(obj_vel[:, :3], palm_rot),
            w_obj=observe.to_frame(np.einsum("bij,bj->bi", obj_rot, obj_vel[:, 3:]), palm_rot),
            lift=self.t >= ep.grasp_steps, **extra_g)
        x = observe.node_features(layout, self.node_valid, self.static_nodes, d=observe.to_frame(d_world, palm_rot),
                                  theta=observe.primitive_state(q, self.proj), theta_dot=observe.primitive_state(qd, self.proj),
                                  contact=force > 1e-6, force=force, **extra_n)
        obs = dict(nodes=x, adjacency=self.adjacency, physical=self.physical, mask=self.mask, node_valid=self.node_valid,
                   closing=self.closing)
        obs["global"] = glob
        return obs, d_world, obj_pos[:, 2].copy()

    def close(self) -> None:
        if self.pool is not None:
            self.pool.shutdown()
