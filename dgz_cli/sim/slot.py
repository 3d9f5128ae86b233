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
    """A (hand, object) scene and its own MjData. Slots of the same (hand, object) share one MjModel:
    resets only set joint values (the wrist slides hold the position, its hinges the orientation)."""

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
        self.wrist_q0 = np.zeros(6)  # wrist joint values at the end of the last reset
        wid = index.wrist_body
        self.mount = quat_to_mat(model.body_quat[wid])  # compiled quaternions are unit
        self.base = model.body_pos[wid].copy()
        self.hinge_axes = index.palm_axes_w.T  # f, l, n in the mount frame

    def bind(self, n_max: int, l_max: int) -> None:
        """Destination rows in the env's padded buffers (N nodes, L joints)."""
        n, l = len(self.idx.node_body), self.n_joints
        self._dest = np.r_[np.arange(n), n_max, n_max + 1]
        self._vdest = np.r_[np.arange(l), l_max + np.arange(6)]

    # -- reset -------------------------------------------------------------------------------
    def reset(self, rng: np.random.Generator) -> None:
        mj, m, d, idx, cfg = self.mj, self.model, self.data, self.idx, self.cfg
        mj.mj_resetData(m, d)
        d.qpos[idx.wrist_qadr[:3]] = [0.0, 0.0, 3.0]  # out of the way while the object settles
        rot = random_rotation(rng)
        lowest = (idx.cloud @ rot.T)[:, 2].min()
        d.qpos[idx.object_qadr:idx.object_qadr + 3] = [0.0, 0.0, -lowest + 0.002]
        d.qpos[idx.object_qadr + 3:idx.object_qadr + 7] = _mat_to_quat(rot)
        d.qpos[idx.hand_qadr] = idx.rest_q
        d.ctrl[:] = 0.0
        d.ctrl[:3] = d.qpos[idx.wrist_qadr[:3]]
        d.ctrl[6:6 + self.n_joints] = idx.rest_q
        mj.mj_step(m, d, nstep=max(1, int(round(cfg.settle_s / cfg.physics_dt))))
        d.qvel[:] = 0.0
        obj_rot = d.xmat[idx.object_body].reshape(3, 3)
        center = d.xpos[idx.object_body] + (idx.cloud @ obj_rot.T).mean(0)
        self.z0 = float(d.xpos[idx.object_body][2])
        # tilt of the approach within the cone (about the palm's f and l axes), any roll about n
        tilt, azim = cfg.approach_cone * np.sqrt(rng.random()), 2 * np.pi * rng.random()
        hinge = np.array([tilt * np.cos(azim), tilt * np.sin(azim), 2 * np.pi * rng.random()])
        r_delta = np.eye(3)
        for axis, angle in zip(self.hinge_axes, hinge):
            r_delta = r_delta @ _axis_angle(axis, angle)
        r_wrist = self.mount @ r_delta
        u = -(r_wrist @ self.hinge_axes[2])  # from the object toward the palm: the palm normal points back
        pos = center + u * cfg.approach_distance - r_wrist @ idx.palm_center_w
        q0 = np.concatenate([pos - self.base, hinge])
        d.qpos[idx.wrist_qadr] = q0
        d.qvel[:] = 0.0
        d.ctrl[:6] = q0
        self.wrist_q0 = q0
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


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
