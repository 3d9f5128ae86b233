"""Safe reading of a robot description (URDF or xacro) into sanitized XML that MuJoCo compiles.

Shared by onboarding and simulation; lives in ``spec`` so every layer can use it. XML is parsed
without DTDs or entity expansion; mesh paths (relative, absolute, ``file://``, ``package://``)
become absolute files; visuals are dropped (MuJoCo cannot decode .glb/.dae and physics does not
need them); any ``<mujoco>`` element the file carries is replaced by dgz's compiler settings.
"""

from __future__ import annotations

import hashlib
import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from dgz_cli.spec.errors import UrdfError


@dataclass(frozen=True)
class RobotXml:
    source: Path
    sha256: str
    root: etree._Element  # sanitized <robot>
    meshes: tuple[Path, ...]


def safe_parse(data: bytes, where: str) -> etree._Element:
    """Parse XML bytes with no DTD loading, no entity expansion and no network access."""
    if b"<!DOCTYPE" in data or b"<!ENTITY" in data:
        raise UrdfError(f"{where}: DOCTYPE/ENTITY declarations are not allowed in a robot description",
                        "remove the <!DOCTYPE ...> block; URDF never needs entities")
    parser = etree.XMLParser(
        resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False, remove_comments=True
    )
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        raise UrdfError(f"{where}: malformed XML: {exc.msg} (line {exc.lineno})",
                        "fix the XML syntax; `xmllint --noout FILE` shows the exact spot") from None
    if root.getroottree().docinfo.internalDTD is not None:
        raise UrdfError(f"{where}: DOCTYPE/ENTITY declarations are not allowed in a robot description",
                        "remove the <!DOCTYPE ...> block; URDF never needs entities")
    return root


def expand_xacro(path: Path, args: dict[str, str]) -> bytes:
    import xacro  # heavy-ish and only needed for .xacro input

    safe_parse(path.read_bytes(), str(path))  # refuse entity bombs before xacro's own parser sees the file
    try:
        doc = xacro.process_file(str(path), mappings=dict(args))
    except Exception as exc:  # xacro raises XacroException, NameError, KeyError, expat errors, ...
        msg = " ".join(str(exc).split()) or type(exc).__name__
        raise UrdfError(f"{path}: xacro expansion failed: {msg}",
                        "check the macro/property named above and the --xacro-arg KEY=VALUE values") from None
    return doc.toxml(encoding="utf-8")


def resolve_mesh(filename: str, urdf_dir: Path) -> Path:
    if filename.startswith("package://"):
        pkg, _, rest = filename[len("package://"):].partition("/")
        bases = [urdf_dir, *urdf_dir.parents]
        bases += [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
        for base in bases:
            for candidate in (base / rest if base.name == pkg else None, base / pkg / rest):
                if candidate is not None and candidate.is_file():
                    return candidate.resolve()
        return (urdf_dir / rest).resolve()
    if filename.startswith("file://"):
        filename = filename[len("file://"):]
    p = Path(filename)
    return (p if p.is_absolute() else urdf_dir / p).resolve()


def read_robot_xml(path: Path, xacro_args: dict[str, str] | None = None) -> RobotXml:
    """Read, expand (xacro), sanitize and resolve the meshes of a robot description."""
    path = Path(path)
    if not path.is_file():
        raise UrdfError(f"{path}: no such file", "check the path, or set --asset-root / DGZ_ASSET_ROOT")
    raw = path.read_bytes()
    is_xacro = path.suffix == ".xacro" or path.name.endswith(".urdf.xacro")
    data = expand_xacro(path, xacro_args or {}) if is_xacro else raw
    root = safe_parse(data, str(path))
    if root.tag != "robot":
        raise UrdfError(f"{path}: root element is <{root.tag}>, expected <robot>", "is this really a URDF file?")
    for el in root.findall("mujoco"):
        root.remove(el)
    urdf_dir = path.parent.resolve()
    meshes: list[Path] = []
    missing: list[str] = []
    for link in root.findall("link"):
        for el in list(link.findall("visual")):
            link.remove(el)
        for el in link.findall("collision"):
            mesh = el.find("geometry/mesh")
            if mesh is None:
                continue
            fname = mesh.get("filename", "")
            resolved = resolve_mesh(fname, urdf_dir)
            if not resolved.is_file():
                missing.append(f"{fname} (link '{link.get('name')}')")
            mesh.set("filename", str(resolved))
            meshes.append(resolved)
    if missing:
        raise UrdfError(f"{path}: missing mesh file {missing[0]}"
                        + (f" and {len(missing) - 1} more" if len(missing) > 1 else ""),
                        "restore the mesh next to the URDF or fix the filename/package:// path")
    return RobotXml(path, hashlib.sha256(raw).hexdigest(), root, tuple(meshes))


def mujoco_xml(robot: RobotXml) -> str:
    """The sanitized URDF with dgz's MuJoCo compiler settings injected (what MuJoCo compiles).

    ``fusestatic="false"`` keeps fingertip/palm frames named in the URDF; ``balanceinertia``
    accepts vendor inertias that violate the triangle inequality; MuJoCo turns <mimic> into
    joint equality constraints.
    """
    root = etree.fromstring(etree.tostring(robot.root), etree.XMLParser(resolve_entities=False, no_network=True))
    mj = etree.Element("mujoco")
    etree.SubElement(mj, "compiler", meshdir=str(robot.source.parent.resolve()), strippath="false",
                     balanceinertia="true", discardvisual="true", fusestatic="false", angle="radian")
    root.insert(0, mj)
    return etree.tostring(root, encoding="unicode")


@contextmanager
def captured_mujoco_warnings():
    """Route MuJoCo's warnings (C-level ``mju_warning`` and the Python ``UserWarning`` that MjSpec
    compilation raises) into a list instead of stderr and ./MUJOCO_LOG.TXT."""
    import warnings as pywarnings

    import mujoco

    messages: list[str] = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(lambda msg: messages.append(" ".join(str(msg).split())))
    try:
        with pywarnings.catch_warnings(record=True) as caught:
            pywarnings.simplefilter("always")
            yield messages
        messages.extend(" ".join(str(w.message).split()) for w in caught)
    finally:
        mujoco.set_mju_user_warning(previous)
