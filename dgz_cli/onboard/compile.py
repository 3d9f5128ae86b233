"""Compile a raw URDF into a MuJoCo model in memory, and pose it.

The asset files are never edited: a ``<mujoco><compiler .../></mujoco>`` element is injected
into the sanitized XML, visuals are already dropped (``.glb``/``.dae`` cannot be decoded),
static bodies are kept (``fusestatic="false"``) so fingertip/palm frames named in the URDF
survive, and MuJoCo turns URDF ``<mimic>`` into joint equality constraints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from lxml import etree

from dgz_cli.onboard.urdf import Kinematics
from dgz_cli.spec.errors import UrdfError
from dgz_cli.spec.urdfxml import RobotXml, captured_mujoco_warnings, mujoco_xml


def compiler_xml(kin: Kinematics) -> str:
    """The URDF XML with dgz's compiler settings injected (what MuJoCo compiles)."""
    root = etree.fromstring(kin.xml, etree.XMLParser(resolve_entities=False, no_network=True))
    return mujoco_xml(RobotXml(kin.source, kin.sha256, root, kin.meshes))


def compile_with_warnings(kin: Kinematics):
    """Return (``mujoco.MjModel`` of the hand fixed to the world at its root link, compiler warnings)."""
    import mujoco

    with captured_mujoco_warnings() as warnings:
        try:
            model = mujoco.MjModel.from_xml_string(compiler_xml(kin))
        except ValueError as exc:
            msg = " ".join(str(exc).split())
            raise UrdfError(f"{kin.source}: MuJoCo cannot compile this URDF: {msg}",
                            "fix the element named in MuJoCo's message (inertia, mesh, joint)") from None
    return model, list(warnings)


def compile_model(kin: Kinematics):
    return compile_with_warnings(kin)[0]


@dataclass
class Poser:
    """Forward kinematics of a compiled hand at arbitrary joint values.

    Mimic joints follow their source joint (``q = multiplier·q_src + offset``), exactly as the
    equality constraints would hold them. Positions are world-frame 3-vectors (m).
    """

    kin: Kinematics
    model: object

    def __post_init__(self) -> None:
        import mujoco

        self._mj = mujoco
        self.data = mujoco.MjData(self.model)
        self.qadr = {}
        for name, j in self.kin.joints.items():
            if j.movable:
                jid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, name)
                if jid < 0:
                    raise UrdfError(f"{self.kin.source}: joint '{name}' vanished in MuJoCo", "report this URDF")
                self.qadr[name] = int(self.model.jnt_qposadr[jid])
        self.body = {}
        for link in self.kin.links:
            bid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, link)
            self.body[link] = bid if bid >= 0 else 0  # the root link is merged into the world body

    def rest(self) -> dict[str, float]:
        """Zero pose clipped into every actuated joint's range."""
        return {j.name: float(np.clip(0.0, j.lower, j.upper)) for j in self.kin.actuated}

    def full(self, q: dict[str, float]) -> dict[str, float]:
        """Actuated values → values for every movable joint (mimics follow, clipped to their range)."""
        out = dict(q)
        for j in self.kin.joints.values():
            if j.movable and j.mimic is not None:
                v = j.mimic.multiplier * out.get(j.mimic.joint, 0.0) + j.mimic.offset
                out[j.name] = float(np.clip(v, j.lower, j.upper)) if j.type != "continuous" else v
        return out

    def pose(self, q: dict[str, float], extra: dict[str, float] | None = None) -> None:
        """Set the model to actuated values ``q`` (+ ``extra`` offsets on any joint) and run kinematics."""
        self.data.qpos[:] = 0.0
        for name, v in self.full(q).items():
            self.data.qpos[self.qadr[name]] = v
        for name, dv in (extra or {}).items():
            self.data.qpos[self.qadr[name]] += dv
        self._mj.mj_kinematics(self.model, self.data)

    def link_pos(self, link: str, local: np.ndarray | None = None) -> np.ndarray:
        b = self.body[link]
        p = self.data.xpos[b].copy()
        if local is not None:
            p = p + self.data.xmat[b].reshape(3, 3) @ local
        return p

    def link_rot(self, link: str) -> np.ndarray:
        return self.data.xmat[self.body[link]].reshape(3, 3).copy()

    def joint_anchor(self, name: str) -> np.ndarray:
        jid = self._mj.mj_name2id(self.model, self._mj.mjtObj.mjOBJ_JOINT, name)
        return self.data.xanchor[jid].copy()

    def joint_axis(self, name: str) -> np.ndarray:
        jid = self._mj.mj_name2id(self.model, self._mj.mjtObj.mjOBJ_JOINT, name)
        return self.data.xaxis[jid].copy()

    def geom_points(self, links: list[str]) -> np.ndarray:
        """World-frame surface sample points (K, 3) of the collision geoms attached to ``links``."""
        mj, m, d = self._mj, self.model, self.data
        bodies = {self.body[l] for l in links}
        pts = []
        for g in range(m.ngeom):
            if m.geom_bodyid[g] not in bodies:
                continue
            rot, pos = d.geom_xmat[g].reshape(3, 3), d.geom_xpos[g]
            if m.geom_type[g] == mj.mjtGeom.mjGEOM_MESH:
                mid = m.geom_dataid[g]
                a, n = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
                local = m.mesh_vert[a:a + n]
            else:
                s = m.geom_size[g]
                ext = np.array([s[0], s[1] if s[1] > 0 else s[0], s[2] if s[2] > 0 else s[0]])
                if m.geom_type[g] == mj.mjtGeom.mjGEOM_CAPSULE:
                    ext = np.array([s[0], s[0], s[1] + s[0]])
                elif m.geom_type[g] == mj.mjtGeom.mjGEOM_CYLINDER:
                    ext = np.array([s[0], s[0], s[1]])
                elif m.geom_type[g] == mj.mjtGeom.mjGEOM_SPHERE:
                    ext = np.array([s[0], s[0], s[0]])
                local = np.concatenate([np.diag(ext), -np.diag(ext)])
            pts.append(local @ rot.T + pos)
        return np.concatenate(pts) if pts else np.zeros((0, 3))
