"""One environment slot: a compiled scene, its MjData, resets and the raw state it exposes."""

from __future__ import annotations

import numpy as np

from dgz_cli.sim.config import EnvConfig
from dgz_cli.sim.objects import ObjectModel, quat_to_mat
from dgz_cli.sim.scene import SceneIndex
from dgz_cli.spec.models import HandSpec


def _mat_to_quat(r: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, r.reshape(-1))
    return q


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return quat_to_mat(q / np.linalg.norm(q))


class Slot:
    """A (hand, object) scene. Each slot owns its MjModel copy because resets move the wrist's
    mount (``body_pos``/``body_quat``) so that the wrist joints start at zero."""

    def __init__(self, spec: HandSpec, obj: ObjectModel, model, index: SceneIndex, cfg: EnvConfig) -> None:
        import mujoco

        self.mj = mujoco
        self.spec, self.obj, self.cfg = spec, obj, cfg
        self.model, self.idx = model, index
        self.data = mujoco.MjData(model)
        self.n_joints = len(index.hand_qadr)
        self.obj_geom = model.geom_bodyid == index.object_body
        self._bodies = np.r_[index.node_body, index.object_body, index.palm_body]
        self._dofs = np.r_[index.hand_dadr, np.arange(index.object_dadr, index.object_dadr + 6)]

        self.z0 = 0.0
        self.mount_rot = np.eye(3)
        # palm frame relative to the wrist mount at the rest pose
        d = self.data
        model.body_pos[index.wrist_body] = 0.0
        model.body_quat[index.wrist_body] = [1, 0, 0, 0]
        d.qpos[:] = model.qpos0
        d.qpos[index.hand_qadr] = index.rest_q
        mujoco.mj_kinematics(model, d)
        r_wp = d.xmat[index.palm_body].reshape(3, 3)
        p_wp = d.xpos[index.palm_body]
        self.palm_axes_w = r_wp @ index.palm_axes  # palm frame axes in the mount frame
        self.palm_center_w = r_wp @ index.palm_center + p_wp
        anchors = d.xpos[index.node_body] + np.einsum("nij,nj->ni", d.xmat[index.node_body].reshape(-1, 3, 3),
                                                      index.node_point)
        # the open hand's node centroid, palm frame: where a scripted grasp puts the object (f, l)
        self.grasp_offset = self.palm_axes_w.T @ (anchors.mean(0) - self.palm_center_w)

    def bind(self, n_max: int, l_max: int) -> None:
        """Destination rows in the env's padded buffers (N nodes, L joints)."""
        n, l = len(self.idx.node_body), self.n_joints
        self._dest = np.r_[np.arange(n), n_max, n_max + 1]
        self._vdest = np.r_[np.arange(l), l_max + np.arange(6)]

    # -- reset -------------------------------------------------------------------------------
    def reset(self, rng: np.random.Generator) -> None:
        mj, m, d, idx, cfg = self.mj, self.model, self.data, self.idx, self.cfg
        mj.mj_resetData(m, d)
        m.body_pos[idx.wrist_body] = [0.0, 0.0, 3.0]  # out of the way while the object settles
        m.body_quat[idx.wrist_body] = [1, 0, 0, 0]
        rot = random_rotation(rng)
        lowest = (idx.cloud @ rot.T)[:, 2].min()
        d.qpos[idx.object_qadr:idx.object_qadr + 3] = [0.0, 0.0, -lowest + 0.002]
        d.qpos[idx.object_qadr + 3:idx.object_qadr + 7] = _mat_to_quat(rot)
        d.qpos[idx.hand_qadr] = idx.rest_q
        d.ctrl[:] = 0.0
        d.ctrl[6:6 + self.n_joints] = idx.rest_q
        mj.mj_step(m, d, nstep=max(1, int(round(cfg.settle_s / cfg.physics_dt))))
        d.qvel[:] = 0.0
        obj_rot = d.xmat[idx.object_body].reshape(3, 3)
        center = d.xpos[idx.object_body] + (idx.cloud @ obj_rot.T).mean(0)
        self.z0 = float(d.xpos[idx.object_body][2])
        # approach direction u: within a cone around +z; palm normal n = −u; random roll about n
        tilt, azim = cfg.approach_cone * np.sqrt(rng.random()), 2 * np.pi * rng.random()
        u = np.array([np.sin(tilt) * np.cos(azim), np.sin(tilt) * np.sin(azim), np.cos(tilt)])
        n = -u
        helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        f0 = np.cross(n, helper)
        f0 /= np.linalg.norm(f0)
        yaw = 2 * np.pi * rng.random()
        f = np.cos(yaw) * f0 + np.sin(yaw) * np.cross(n, f0)
        palm_world = np.stack([f, np.cross(n, f), n], axis=1)
        mount = palm_world @ self.palm_axes_w.T
        pos = center + u * cfg.approach_distance - mount @ self.palm_center_w
        m.body_pos[idx.wrist_body] = pos
        m.body_quat[idx.wrist_body] = _mat_to_quat(mount)
        self.mount_rot = mount
        d.qpos[idx.wrist_qadr] = 0.0
        d.qvel[:] = 0.0
        d.ctrl[:6] = 0.0
        mj.mj_forward(m, d)

    # -- physics -----------------------------------------------------------------------------
    def step(self, ctrl: np.ndarray) -> bool:
        """Run one control period; returns False if MuJoCo became unstable (NaN, or the automatic
        reset MuJoCo performs on a bad acceleration, which sends ``data.time`` backwards)."""
        d = self.data
        d.ctrl[:len(ctrl)] = ctrl
        expected = d.time + self.cfg.substeps * self.model.opt.timestep
        self.mj.mj_step(self.model, d, nstep=self.cfg.substeps)
        return abs(d.time - expected) < 1e-6 and bool(np.isfinite(d.qpos).all())

    def gather(self, buf: dict[str, np.ndarray], b: int) -> None:
        """Copy this slot's raw state into row ``b`` of the env's batch buffers (runs in a worker
        thread right after stepping, so it overlaps the other thread's physics). Rows of ``xpos`` /
        ``xmat``: the N node bodies (padded), then the object body, then the palm body."""
        d = self.data
        buf["xpos"][b, self._dest] = d.xpos[self._bodies]
        buf["xmat"][b, self._dest] = d.xmat[self._bodies]
        buf["q"][b, :self.n_joints] = d.qpos[self.idx.hand_qadr]
        buf["wq"][b] = d.qpos[self.idx.wrist_qadr]
        buf["qd"][b, self._vdest] = d.qvel[self._dofs]
        force = buf["force"][b]
        force[:] = 0.0
        if d.ncon:
            self.contacts(force)

    def contacts(self, force: np.ndarray) -> None:
        """Add the normal force (N) of each hand–object contact to its node's entry of ``force``."""
        d = self.data
        ncon = d.ncon
        if ncon == 0:
            return
        g1, g2 = d.contact.geom1[:ncon], d.contact.geom2[:ncon]
        node = np.where(self.obj_geom[g1], self.idx.geom_node[g2], np.where(self.obj_geom[g2], self.idx.geom_node[g1], -1))
        sel = np.nonzero((node >= 0) & (d.contact.efc_address[:ncon] >= 0))[0]
        elliptic = self.model.opt.cone == self.mj.mjtCone.mjCONE_ELLIPTIC
        for k in sel:  # normal force: first row of an elliptic cone, sum of a pyramid's facets
            adr, dim = d.contact.efc_address[k], d.contact.dim[k]
            force[node[k]] += d.efc_force[adr] if elliptic or dim == 1 else d.efc_force[adr:adr + 2 * (dim - 1)].sum()
