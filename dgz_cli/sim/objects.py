"""Graspable objects: the 45 YCB objects of the CrossDex split (from the asset root) and a few
built-in primitives in YCB-like sizes that need no assets.

Every object is a free body whose frame sits at its collision geometry's centroid-ish origin;
``surface_points`` samples its collision surface (object frame) for the node → surface vectors.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dgz_cli.spec.catalog import asset_root
from dgz_cli.spec.errors import AssetError

YCB_DIR = Path("objects") / "ycb45"

# name → (MuJoCo geom type, size, mass kg); sizes follow YCB items of similar shape
PRIMITIVES: dict[str, tuple[str, tuple[float, ...], float]] = {
    "sphere": ("sphere", (0.035,), 0.15),             # ~ 056_tennis_ball / 017_orange
    "box": ("box", (0.03, 0.045, 0.05), 0.3),          # ~ a small cereal box, half-sizes
    "cylinder": ("cylinder", (0.033, 0.05), 0.35),     # ~ 005_tomato_soup_can, radius / half-height
    "capsule": ("capsule", (0.02, 0.05), 0.12),        # ~ 040_large_marker (fatter), radius / half-length
}


@dataclass(frozen=True)
class ObjectModel:
    name: str
    kind: str  # "primitive" | "ycb"
    path: Path | None  # model.xml for YCB objects


def ycb_names(root_option: str | None = None) -> list[str]:
    root = asset_root(root_option, required=True)
    folder = root / YCB_DIR
    if not folder.is_dir():
        raise AssetError(f"{folder} not found", "the asset root must contain objects/ycb45/ (see docs)")
    return sorted(p.parent.name for p in folder.glob("*/model.xml"))


def resolve_objects(spec: str, root_option: str | None = None) -> list[ObjectModel]:
    """``ycb45``, ``primitives``, or a comma-separated list of object names."""
    out: list[ObjectModel] = []
    for token in [t.strip() for t in spec.split(",") if t.strip()]:
        if token == "ycb45":
            out += [resolve_objects(n, root_option)[0] for n in ycb_names(root_option)]
        elif token == "primitives":
            out += [ObjectModel(n, "primitive", None) for n in PRIMITIVES]
        elif token in PRIMITIVES:
            out.append(ObjectModel(token, "primitive", None))
        else:
            out.append(ObjectModel(token, "ycb", _ycb_model(token, root_option)))
    if not out:
        raise AssetError("no objects selected", "pass e.g. --objects ycb45 or --objects sphere,box")
    return out


MAX_MODEL_BYTES = 64 * 1024 * 1024


def _ycb_model(token: str, root_option: str | None) -> Path:
    """``<asset root>/objects/ycb45/<token>/model.xml``: ``token`` is one folder name (no path, no ``..``)
    and the model a regular file of bounded size."""
    import stat

    root = asset_root(root_option, required=True)
    folder = root / YCB_DIR
    known = f"use ycb45, primitives ({', '.join(PRIMITIVES)}) or a folder name under {folder}"
    if (not token or token in (".", "..") or "/" in token or "\\" in token or "\x00" in token
            or token != token.strip() or Path(token).is_absolute()):
        raise AssetError(f"object name {token!r} is not a plain folder name", known)
    path = folder / token / "model.xml"
    try:
        st = os.stat(path)
    except OSError:
        raise AssetError(f"unknown object '{token}' (no {path})", known) from None
    if not stat.S_ISREG(st.st_mode):
        raise AssetError(f"object '{token}': {path} is not a regular file", known)
    if st.st_size > MAX_MODEL_BYTES:
        raise AssetError(f"object '{token}': {path} is {st.st_size} bytes (more than {MAX_MODEL_BYTES >> 20} MB)",
                         "is this really a MuJoCo model?")
    return path


def object_spec(obj: ObjectModel, visual: bool):
    """An ``MjSpec`` whose world holds one free body named ``object``."""
    import mujoco

    if obj.kind == "primitive":
        gtype, size, mass = PRIMITIVES[obj.name]
        s = mujoco.MjSpec()
        body = s.worldbody.add_body(name="object")
        body.add_freejoint(name="object_joint")
        body.add_geom(type=getattr(mujoco.mjtGeom, f"mjGEOM_{gtype.upper()}"), size=list(size) + [0] * (3 - len(size)),
                      mass=mass, rgba=[0.85, 0.55, 0.2, 1], friction=[1.0, 0.005, 0.0001])
        return s
    s = mujoco.MjSpec.from_file(str(obj.path))
    for m in s.meshes:  # absolute paths, so the object survives being attached into another spec
        m.file = str((obj.path.parent / (s.meshdir or "") / m.file).resolve())
    body = s.worldbody.first_body()
    body.name = "object"
    for g in list(body.geoms):
        if g.contype == 0 and g.conaffinity == 0 and not visual:
            s.delete(g)
        elif g.contype != 0:
            g.friction = [1.0, 0.005, 0.0001]
    if not visual:
        for m in list(s.meshes):
            if "visual" in m.name:
                s.delete(m)
        for mat in list(s.materials):
            s.delete(mat)
    return s


def surface_points(model, body_id: int, n: int, seed: int = 0) -> np.ndarray:
    """(n, 3) points sampled uniformly (by area) on the collision geoms of ``body_id``, body frame."""
    import mujoco

    rng = np.random.default_rng(seed)
    tris, areas = [], []
    for g in range(model.ngeom):
        if model.geom_bodyid[g] != body_id or model.geom_contype[g] == 0:
            continue
        rot = quat_to_mat(model.geom_quat[g])
        pos = model.geom_pos[g]
        t = model.geom_type[g]
        if t == mujoco.mjtGeom.mjGEOM_MESH:
            mid = model.geom_dataid[g]
            v = model.mesh_vert[model.mesh_vertadr[mid]:model.mesh_vertadr[mid] + model.mesh_vertnum[mid]]
            f = model.mesh_face[model.mesh_faceadr[mid]:model.mesh_faceadr[mid] + model.mesh_facenum[mid]]
            tri = v[f] @ rot.T + pos
        else:
            tri = _primitive_triangles(t, model.geom_size[g]) @ rot.T + pos
        tris.append(tri)
        areas.append(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1))
    tri = np.concatenate(tris)
    area = np.concatenate(areas)
    idx = rng.choice(len(tri), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[idx]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def quat_to_mat(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _primitive_triangles(gtype: int, size: np.ndarray, res: int = 24) -> np.ndarray:
    """A triangulated surface of a MuJoCo primitive (sphere/capsule/cylinder/box), geom frame."""
    import mujoco

    if gtype == mujoco.mjtGeom.mjGEOM_BOX:
        c = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * size[:3]
        faces = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
        return np.array([c[[a, b, cc]] for a, b, cc, d in faces] + [c[[a, cc, d]] for a, b, cc, d in faces])
    th = np.linspace(0, 2 * np.pi, res, endpoint=False)
    if gtype == mujoco.mjtGeom.mjGEOM_SPHERE:
        r, half = size[0], 0.0
    else:
        r, half = size[0], size[1]
    ph = np.linspace(-np.pi / 2, np.pi / 2, res // 2 + 1)
    rings = []
    for p in ph:
        z = r * np.sin(p)
        rad = r * np.cos(p)
        if gtype == mujoco.mjtGeom.mjGEOM_CYLINDER:
            z, rad = np.sign(p) * half if p != 0 else 0.0, (r if abs(p) < np.pi / 2 else 0.0)
        else:
            z = z + np.sign(p) * half
        rings.append(np.stack([rad * np.cos(th), rad * np.sin(th), np.full(res, z)], 1))
    tris = []
    for a, b in zip(rings[:-1], rings[1:]):
        for k in range(res):
            k2 = (k + 1) % res
            tris += [(a[k], a[k2], b[k]), (a[k2], b[k2], b[k])]
    return np.array(tris)
