"""Forward kinematics of the hand alone, from its HandSpec: palm frame, node anchors and fingertips.

The URDF is compiled exactly as the sim backend compiles it (:func:`dgz_cli.hw.sim_hand.build_model`, which
uses the shared sanitizer in :mod:`dgz_cli.spec.urdfxml`, as onboarding and the training scenes do). Only
``mj_kinematics`` runs: actuated joints take the given values and every mimic joint of the spec follows
its source (``q = multiplier · q_source + offset``), as the scenes' equality constraints hold it.
Frames: the hand's root frame (the URDF root) and the *palm frame* (origin ``spec.palm.center``, axes
f, l, n), the frame every observation is expressed in.
"""

from __future__ import annotations

import numpy as np

from dgz_cli.spec.models import HandSpec

_CACHE: dict[tuple, "HandKinematics"] = {}


class HandKinematics:
    def __init__(self, spec: HandSpec, asset_root: str | None = None) -> None:
        import mujoco

        from dgz_cli.hw.sim_hand import build_model

        self._mj = mujoco
        self.spec = spec
        self.model, _, self.qadr = build_model(spec, asset_root)
        self.data = mujoco.MjData(self.model)
        index = {r.joint: i for i, r in enumerate(spec.joints)}
        self.mimic = []  # (qpos address, source index, multiplier, offset, lower, upper)
        for m in spec.mimic:
            jid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, m.joint)
            if jid < 0 or m.source not in index:
                continue
            lo, hi = self.model.jnt_range[jid] if self.model.jnt_limited[jid] else (-np.inf, np.inf)
            self.mimic.append((int(self.model.jnt_qposadr[jid]), index[m.source], m.multiplier, m.offset, lo, hi))

        def body(link: str) -> int:  # the URDF root link is merged into the world body (id 0)
            return max(0, mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, link))

        self.node_body = np.array([body(n.anchor_link) for n in spec.nodes])
        self.node_point = np.array([n.anchor_point for n in spec.nodes], dtype=float)  # (N, 3) body frames
        self.palm_body = body(spec.palm.link)
        self.palm_axes = np.stack([spec.palm.finger_axis, spec.palm.lateral, spec.palm.normal], axis=1)
        self.palm_center = np.array(spec.palm.center, dtype=float)
        self.rest = np.clip(0.0, [r.lower for r in spec.joints], [r.upper for r in spec.joints])

    @classmethod
    def for_spec(cls, spec: HandSpec, asset_root: str | None = None) -> "HandKinematics":
        """One compiled model per (spec, URDF hash, asset root) and process."""
        key = (spec.name, spec.provenance.urdf, spec.provenance.urdf_sha256, asset_root)
        if key not in _CACHE:
            _CACHE[key] = cls(spec, asset_root)
        return _CACHE[key]

    def pose(self, q: np.ndarray) -> None:
        """Set the actuated joints (L,) rad, spec order; mimics follow; run kinematics."""
        d = self.data
        d.qpos[:] = 0.0
        q = np.asarray(q, dtype=float)
        d.qpos[self.qadr] = q
        for adr, src, mult, off, lo, hi in self.mimic:
            d.qpos[adr] = np.clip(mult * q[src] + off, lo, hi)
        self._mj.mj_kinematics(self.model, d)

    def palm_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """Palm axes (3, 3; columns f, l, n) and centre (3,) in the root frame, at the current pose."""
        r = self.data.xmat[self.palm_body].reshape(3, 3)
        return r @ self.palm_axes, self.data.xpos[self.palm_body] + r @ self.palm_center

    def anchors_root(self) -> np.ndarray:
        """(N, 3) node anchor points in the root frame, at the current pose."""
        rot = self.data.xmat[self.node_body].reshape(-1, 3, 3)
        return self.data.xpos[self.node_body] + np.einsum("nij,nj->ni", rot, self.node_point)

    def anchors_palm(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) node anchor points in the palm frame for joint values ``q`` (L,)."""
        self.pose(q)
        r, c = self.palm_frame()
        return (self.anchors_root() - c) @ r

    def fingertips(self, q: np.ndarray) -> dict[str, np.ndarray]:
        """Finger class → (3,) fingertip anchor in the palm frame (fingertip nodes only)."""
        pts = self.anchors_palm(q)
        return {n.finger: pts[i] for i, n in enumerate(self.spec.nodes) if n.type == "fingertip"}
