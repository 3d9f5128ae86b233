"""Compile a raw URDF into a MuJoCo model in memory, and pose it.

The asset files are never edited: a ``<mujoco><compiler .../></mujoco>`` element is injected
into the sanitized XML, visuals are already dropped (``.glb``/``.dae`` cannot be decoded),
static bodies are kept (``fusestatic="false"``) so fingertip/palm frames named in the URDF
survive, and MuJoCo turns URDF ``<mimic>`` into joint equality constraints.
"""

from __future__ import annotations

import numpy as np
from lxml import etree

from dgz_cli.onboard.urdf import Kinematics
from dgz_cli.spec.errors import UrdfError
from dgz_cli.spec.kinematics import ForwardKinematics, rest_pose
from dgz_cli.spec.models import MimicJoint
from dgz_cli.spec.urdfxml import RobotXml, captured_mujoco_warnings, mujoco_xml


def compiler_xml(kin: Kinematics) -> str:
    """The URDF XML with dgz's compiler settings injected (what MuJoCo compiles)."""
    root = etree.fromstring(kin.xml, etree.XMLParser(resolve_entities=False, no_network=True))
    return mujoco_xml(RobotXml(kin.source, kin.sha256, root, kin.meshes))


def compile_with_warnings(kin: Kinematics):
    """Return (``mujoco.MjModel`` of the hand fixed to the world at its root link, compiler warnings).

    Onboarding only poses the hand and reads its geometry, so collisions are switched off (contype and
    conaffinity 0, kept with ``discardvisual`` off): MuJoCo then skips the convex hulls of the collision
    meshes, most of the compile time (LEAP: docs/benchmarks.md); mesh vertices and body frames are the same."""
    import mujoco

    with captured_mujoco_warnings() as warnings:
        try:
            spec = mujoco.MjSpec.from_string(compiler_xml(kin))
            spec.compiler.discardvisual = False
            for geom in spec.geoms:
                geom.contype, geom.conaffinity = 0, 0
            model = spec.compile()
        except ValueError as exc:
            msg = " ".join(str(exc).split())
            raise UrdfError(f"{kin.source}: MuJoCo cannot compile this URDF: {msg}",
                            "fix the element named in MuJoCo's message (inertia, mesh, joint)") from None
    return model, list(warnings)


def compile_model(kin: Kinematics):
    return compile_with_warnings(kin)[0]


class Poser:
    """Forward kinematics of a compiled hand at arbitrary joint values, by joint and link name: the shared
    :class:`~dgz_cli.spec.kinematics.ForwardKinematics` driven by the URDF's actuated joints, its mimic
    joints following their source (``q = multiplier·q_src + offset``), exactly as the equality constraints
    would hold them. Positions are world-frame 3-vectors (m)."""

    def __init__(self, kin: Kinematics, model) -> None:
        self.kin, self.model = kin, model
        self.actuated = [j.name for j in kin.actuated]
        mimic = [MimicJoint(joint=j.name, source=j.mimic.joint, multiplier=j.mimic.multiplier,
                            offset=j.mimic.offset, node=None)
                 for j in kin.joints.values() if j.movable and j.mimic is not None]
        try:
            self.fk = ForwardKinematics(model, self.actuated, mimic)
        except UrdfError as exc:
            raise UrdfError(f"{kin.source}: {exc.message}", "report this URDF") from None
        self.data = self.fk.data
        self.body = {link: self.fk.body(link) for link in kin.links}

    def rest(self) -> dict[str, float]:
        """Zero pose clipped into every actuated joint's range."""
        values = rest_pose([j.lower for j in self.kin.actuated], [j.upper for j in self.kin.actuated])
        return dict(zip(self.actuated, values.tolist()))

    def pose(self, q: dict[str, float], extra: dict[str, float] | None = None) -> None:
        """Set the model to actuated values ``q`` (missing ones 0; mimics follow) + ``extra`` offsets on any
        joint, and run kinematics."""
        self.fk.pose(np.array([q.get(name, 0.0) for name in self.actuated]), extra)

    def value(self, joint: str) -> float:
        """Value of any movable joint at the current pose (a mimic joint's as it follows its source)."""
        return self.fk.value(joint)

    def link_pos(self, link: str, local: np.ndarray | None = None) -> np.ndarray:
        b = self.body[link]
        p = self.data.xpos[b].copy()
        if local is not None:
            p = p + self.data.xmat[b].reshape(3, 3) @ local
        return p

    def link_rot(self, link: str) -> np.ndarray:
        return self.data.xmat[self.body[link]].reshape(3, 3).copy()

    def joint_anchor(self, name: str) -> np.ndarray:
        return self.data.xanchor[self.fk.joint_id(name)].copy()

    def joint_axis(self, name: str) -> np.ndarray:
        return self.data.xaxis[self.fk.joint_id(name)].copy()

    def geom_points(self, links: list[str]) -> np.ndarray:
        """World-frame surface sample points (K, 3) of the collision geoms attached to ``links``."""
        import mujoco as mj

        m, d = self.model, self.data
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
