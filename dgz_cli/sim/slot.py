"""One environment slot: a compiled scene, its MjData, resets and the raw state it exposes."""

from __future__ import annotations

import numpy as np

from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.sim.objects import ObjectModel, quat_to_mat
from dgz_cli.sim.scene import SceneIndex
from dgz_cli.spec.models import HandSpec


def _mat_to_quat(r: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, r.reshape(-1))
    return q


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """(3, 3) rotation drawn uniformly over all rotations."""
    q = rng.normal(size=4)
    return quat_to_mat(q / np.linalg.norm(q))


def random_yaw(rng: np.random.Generator) -> np.ndarray:
    """(3, 3) rotation about world z by a uniform angle: the model's own up axis stays up."""
    c, s = np.cos(a := 2 * np.pi * rng.random()), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# Where the wrist waits (m, world frame) while the object settles on the table: far above anything it could touch.
PARKED_WRIST_XYZ = (0.0, 0.0, 3.0)


class Slot:
    """A (hand, object) scene and its own MjData. Slots of the same (hand, object) share one MjModel:
    resets only set joint values (the wrist slides hold the position, its hinges the orientation)."""

    def __init__(self, spec: HandSpec, obj: ObjectModel, model, index: SceneIndex, cfg: EnvConfig,
                 pair_node: np.ndarray | None = None) -> None:
        import mujoco

        self.mj = mujoco
        self.spec, self.obj, self.cfg = spec, obj, cfg
        self.model, self.idx = model, index
        self.data = mujoco.MjData(model)
        self.n_joints = len(index.hand_qadr)
        self.pair_node = contact_table(model, index) if pair_node is None else pair_node
        self._elliptic = model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
        self._period = cfg.contract.episode.substeps * model.opt.timestep
        self._ctrl = self.data.ctrl  # views into MjData stay valid: its arrays are never reallocated
        self._copies: tuple = ()
        self._force = np.zeros(len(index.node_body))
        self.stash_contacts = False
        self.con: tuple | None = None  # (geom pairs, efc addresses, efc_force) views, see ``gather``
        self.z0 = 0.0
        self.wrist_q0 = np.zeros(6)  # wrist joint values at the end of the last reset
        wid = index.wrist_body
        self.mount = quat_to_mat(model.body_quat[wid])  # compiled quaternions are unit
        self.base = model.body_pos[wid].copy()
        self.hinge_axes = index.palm_axes_w.T  # f, l, n in the mount frame
        ob = index.object_body  # the compiled dynamics that set_dynamics scales
        self._nominal = (model.body_mass[ob].copy(), model.body_inertia[ob].copy(), model.geom_friction.copy(),
                         model.actuator_forcerange.copy())
        self.dynamics = (1.0, 1.0, 1.0)  # scales of the object's mass, the contact friction, the finger force limits

    def bind(self, xpos: np.ndarray, xmat: np.ndarray, qpos: np.ndarray, qvel: np.ndarray, force: np.ndarray,
             stash_contacts: bool = False) -> None:
        """Where :meth:`gather` copies this slot's raw state: rows of the env's per-slot buffers, at least
        (nbody, 3), (nbody, 9), (nq,), (nv,) long, and its (n_nodes,) contact-force row. With
        ``stash_contacts`` (elliptic cones only) :meth:`gather` leaves the contacts in ``con`` for the env
        to turn into forces for many slots at once, and does not touch ``force``."""
        d, m = self.data, self.model
        self._copies = ((xpos[:m.nbody], d.xpos), (xmat[:m.nbody], d.xmat), (qpos[:m.nq], d.qpos),
                        (qvel[:m.nv], d.qvel))
        self._force = force
        self.stash_contacts = stash_contacts and self._elliptic

    # -- reset -------------------------------------------------------------------------------
    def set_dynamics(self, mass: float, friction: float, finger_force: float) -> None:
        """Scale the compiled model's nominal object mass and inertia, every geom's friction coefficients and
        the finger actuators' force limits (the wrist's six are left alone) by these factors (1 = as compiled),
        then recompute the model's derived constants. Only for a slot with its own model
        (``EnvConfig.dynamics_noise``): slots of one (hand, object) share theirs otherwise."""
        mass0, inertia0, friction0, force0 = self._nominal
        m, ob = self.model, self.idx.object_body
        m.body_mass[ob] = mass0 * mass
        m.body_inertia[ob] = inertia0 * mass
        m.geom_friction[:] = friction0 * friction
        m.actuator_forcerange[6:] = force0[6:] * finger_force
        self.mj.mj_setConst(m, self.data)
        self.dynamics = (float(mass), float(friction), float(finger_force))

    def reset(self, rng: np.random.Generator) -> None:
        mj, m, d, idx, cfg = self.mj, self.model, self.data, self.idx, self.cfg
        mj.mj_resetData(m, d)
        d.qpos[idx.wrist_qadr[:3]] = PARKED_WRIST_XYZ
        rot = random_yaw(rng) if cfg.object_orientation == "upright" else random_rotation(rng)
        lowest = (idx.cloud @ rot.T)[:, 2].min()
        d.qpos[idx.object_qadr:idx.object_qadr + 3] = [0.0, 0.0, -lowest + 0.002]
        d.qpos[idx.object_qadr + 3:idx.object_qadr + 7] = _mat_to_quat(rot)
        d.qpos[idx.hand_qadr] = idx.start_q
        d.ctrl[:] = 0.0
        d.ctrl[:3] = d.qpos[idx.wrist_qadr[:3]]
        d.ctrl[6:6 + self.n_joints] = idx.start_q
        mj.mj_step(m, d, nstep=max(1, int(round(cfg.settle_s / cfg.contract.episode.physics_dt))))
        d.qvel[:] = 0.0
        obj_rot = d.xmat[idx.object_body].reshape(3, 3)
        center = d.xpos[idx.object_body] + (idx.cloud @ obj_rot.T).mean(0)
        self.z0 = float(d.xpos[idx.object_body][2])
        # tilt of the approach within the cone (about the palm's f and l axes), any roll about n
        tilt, azim = cfg.approach_cone * np.sqrt(rng.random()), 2 * np.pi * rng.random()
        hinge = np.array([tilt * np.cos(azim), tilt * np.sin(azim), 2 * np.pi * rng.random()])
        if cfg.roll in ("narrow", "clear"):  # of evenly spaced rolls, the one closing across the narrowest width
            pts = idx.cloud @ obj_rot.T
            rolls = hinge[2] + 2 * np.pi * np.arange(cfg.roll_candidates) / cfg.roll_candidates
            rots = [self._wrist_rot(np.array([hinge[0], hinge[1], r])) for r in rolls]
            widths = np.array([np.ptp(pts @ (rot @ self.hinge_axes.T @ idx.closing_axis)) for rot in rots])
            lowest = (np.array([self._lowest_at_target(rot, center) for rot in rots]) if cfg.roll == "clear"
                      else None)  # ... among those whose hand would clear the table at the guidance target
            hinge[2] = rolls[pick_roll(widths, lowest, cfg.clearance_slack, cfg.clearance_depth)]
        r_wrist = self._wrist_rot(hinge)
        u = -(r_wrist @ self.hinge_axes[2])  # from the object toward the palm: the palm normal points back
        pos = center + u * cfg.approach_distance - r_wrist @ idx.palm_center_w
        q0 = np.concatenate([pos - self.base, hinge])
        d.qpos[idx.wrist_qadr] = q0
        d.qvel[:] = 0.0
        d.ctrl[:6] = q0
        self.wrist_q0 = q0
        mj.mj_forward(m, d)

    def _lowest_at_target(self, r_wrist: np.ndarray, target: np.ndarray) -> float:
        """Height (m, table at 0) of the lowest corner of the wrist node's collision boxes (palm, forearm) with
        the wrist at rotation ``r_wrist`` (3, 3) and the open hand's grasp point at ``target`` (3,) world — where the
        wrist guidance would take it with nothing in the way."""
        hull = self.idx.hull_g
        if not len(hull):  # a wrist node without collision geometry cannot touch the table
            return float("inf")
        return float(target[2] + (hull @ r_wrist[2]).min())

    def _wrist_rot(self, hinge: np.ndarray) -> np.ndarray:
        """(3, 3) wrist body rotation (world) for the three hinge angles about the palm's f, l, n axes."""
        r_delta = np.eye(3)
        for axis, angle in zip(self.hinge_axes, hinge):
            r_delta = r_delta @ _axis_angle(axis, angle)
        return self.mount @ r_delta

    # -- physics -----------------------------------------------------------------------------
    def step(self, ctrl: np.ndarray) -> bool:
        """Run one control period; returns False if MuJoCo became unstable (NaN, or the automatic
        reset MuJoCo performs on a bad acceleration, which sends ``data.time`` backwards)."""
        return self.advance(ctrl) and bool(np.isfinite(self.data.qpos).all())

    def advance(self, ctrl: np.ndarray) -> bool:
        """:meth:`step` without the NaN check (the env checks the gathered ``qpos`` of the whole batch)."""
        d = self.data
        self._ctrl[:len(ctrl)] = ctrl
        expected = d.time + self._period
        self.mj.mj_step(self.model, d, nstep=self.cfg.contract.episode.substeps)
        return abs(d.time - expected) < 1e-6

    def gather(self) -> None:
        """Copy this slot's raw state (whole ``xpos``, ``xmat``, ``qpos``, ``qvel``: one contiguous copy
        each) into the rows given to :meth:`bind`, and its contacts: views of the contacts' geom pairs and
        constraint addresses and of ``efc_force`` into ``con`` (valid until the next step; the env turns
        them into forces for the whole batch at once), or, without ``stash_contacts``, the per-node forces
        into the force row. Runs in a worker thread right after stepping, so it overlaps the other
        thread's physics; the env picks the bodies and joints it needs for the batch, vectorized."""
        d = self.data
        for dst, src in self._copies:
            dst[...] = src
        if not self.stash_contacts:
            self.contacts(self._force)
            return
        ncon = d.ncon
        if ncon:
            c = d.contact
            self.con = (c.geom[:ncon], c.efc_address[:ncon], d.efc_force)
        else:
            self.con = None

    def contacts(self, force: np.ndarray) -> None:
        """Set ``force`` (n_nodes,) to the summed normal force (N) of the hand–object contacts of each node."""
        d = self.data
        ncon = d.ncon
        if ncon == 0:
            force[:] = 0.0
            return
        c = d.contact
        adr = c.efc_address[:ncon]
        node = self.pair_node[c.geom1[:ncon], c.geom2[:ncon]]
        sel = (node >= 0) & (adr >= 0)
        if self._elliptic:  # normal force: the first row of each contact's cone
            # bincount adds in contact order from 0.0, exactly like a loop of ``force[node] += f``
            force[:] = np.bincount(node[sel], weights=d.efc_force[adr[sel]], minlength=len(force))
            return
        force[:] = 0.0
        for k in np.nonzero(sel)[0]:  # pyramidal cones: the sum of the facets (a frictionless contact has one row)
            a, dim = adr[k], c.dim[k]
            force[node[k]] += d.efc_force[a] if dim == 1 else d.efc_force[a:a + 2 * (dim - 1)].sum()


def pick_roll(widths: np.ndarray, lowest: np.ndarray | None = None, slack: float = 0.0, depth: float = 0.0) -> int:
    """Index of the roll candidate to start from: the narrowest closing width (K,) m, among the candidates whose
    hand stays above the table (``lowest`` (K,) m ≥ −``depth``) — or, when none does, whose ``lowest`` is within
    ``slack`` m of the best; ``lowest`` None: all candidates."""
    eligible = (np.ones(len(widths), bool) if lowest is None
                else lowest >= min(-depth, lowest.max() - slack))
    return int(np.argmin(np.where(eligible, widths, np.inf)))


def contact_table(model, index: SceneIndex) -> np.ndarray:
    """(ngeom, ngeom) int: for a contact between geoms (g1, g2), the node of the hand geom when the
    other one belongs to the object, else -1."""
    obj = model.geom_bodyid == index.object_body
    node = np.asarray(index.geom_node)
    return np.where(obj[:, None], node[None, :], np.where(obj[None, :], node[:, None], -1)).astype(np.int64)


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix of ``angle`` about the unit ``axis`` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
