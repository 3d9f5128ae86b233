"""Read a URDF (or xacro) safely into a validated kinematic tree.

XML is parsed without DTDs or entity expansion; xacro is expanded with the ``xacro``
package; the joint semantics are read directly from the sanitized XML (yourdfpy's fields and defaults, without importing yourdfpy and trimesh); mesh paths (relative, absolute,
``package://``) are resolved to absolute files and missing ones are reported by name.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lxml import etree

from dgz_cli.spec.errors import UrdfError
from dgz_cli.spec.urdfxml import read_robot_xml

MOVABLE_TYPES = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class Mimic:
    joint: str
    multiplier: float
    offset: float


@dataclass(frozen=True)
class Joint:
    """One URDF joint. ``origin`` is the 4×4 parent-link → joint transform, ``axis`` a unit 3-vector."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    lower: float
    upper: float
    velocity: float
    effort: float
    damping: float
    mimic: Mimic | None

    @property
    def movable(self) -> bool:
        return self.type in MOVABLE_TYPES

    @property
    def actuated(self) -> bool:
        return self.movable and self.mimic is None


@dataclass(frozen=True)
class Kinematics:
    """A validated URDF kinematic tree plus the sanitized XML that MuJoCo compiles."""

    source: Path
    sha256: str
    xml: bytes
    root: str
    links: tuple[str, ...]
    joints: dict[str, Joint]
    meshes: tuple[Path, ...] = field(default=())

    def children(self, link: str) -> list[Joint]:
        return [j for j in self.joints.values() if j.parent == link]

    def parent_joint(self, link: str) -> Joint | None:
        for j in self.joints.values():
            if j.child == link:
                return j
        return None

    @property
    def actuated(self) -> list[Joint]:
        """Actuated joints in URDF document order (the default command order)."""
        return [j for j in self.joints.values() if j.actuated]

    def subtree_joints(self, link: str) -> list[Joint]:
        out: list[Joint] = []
        stack = [link]
        while stack:
            for j in self.children(stack.pop()):
                out.append(j)
                stack.append(j.child)
        return out


def _finite(value, where: str, fix: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise UrdfError(f"{where} is '{value}', not a number", fix) from None
    if not math.isfinite(number):
        raise UrdfError(f"{where} is {value}", fix)
    return number


def load_kinematics(path: Path, xacro_args: dict[str, str] | None = None) -> Kinematics:
    """Read ``path`` (URDF or xacro), validate it and resolve its meshes.

    Raises :class:`UrdfError` with the file and element named for every problem found.
    """
    robot = read_robot_xml(path, xacro_args)
    path, root = robot.source, robot.root

    names = [el.get("name") for el in root.findall("link")]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise UrdfError(f"{path}: duplicate link name '{dup[0]}'", "every <link name=...> must be unique")
    jnames = [el.get("name") for el in root.findall("joint")]
    dupj = sorted({n for n in jnames if jnames.count(n) > 1})
    if dupj:
        raise UrdfError(f"{path}: duplicate joint name '{dupj[0]}'", "every <joint name=...> must be unique")

    for el in root.findall("joint"):  # name the joint for unparseable numbers before they are read
        for tag, attrs in (("limit", ("lower", "upper", "effort", "velocity")), ("dynamics", ("damping", "friction")),
                           ("mimic", ("multiplier", "offset"))):
            sub = el.find(tag)
            for attr in attrs if sub is not None else ():
                if sub.get(attr) is not None:
                    _finite(sub.get(attr), f"{path}: joint '{el.get('name')}' {tag} {attr}", f"set a finite {attr}")
    xml = etree.tostring(root, encoding="utf-8")
    joints = _read_joints(path, xml)
    links = tuple(n for n in names if n)
    root_link = _check_tree(path, links, joints)
    if not any(j.actuated for j in joints.values()):
        raise UrdfError(f"{path}: no actuated joint (every joint is fixed or mimic)",
                        "a hand needs at least one revolute/continuous/prismatic joint without <mimic>")
    return Kinematics(path, robot.sha256, xml, root_link, links, joints, robot.meshes)


def _origin(el, where: str) -> np.ndarray:
    """4×4 transform of an ``<origin xyz rpy>`` element (URDF: R = Rz(yaw)·Ry(pitch)·Rx(roll))."""
    out = np.eye(4)
    if el is None:
        return out
    try:
        xyz = [float(v) for v in (el.get("xyz") or "0 0 0").split()]
        r, p, y = [float(v) for v in (el.get("rpy") or "0 0 0").split()]
    except ValueError:
        raise UrdfError(f"{where}: <origin> is not three numbers xyz and three rpy", "fix the <origin xyz rpy> values") from None
    if len(xyz) != 3:
        raise UrdfError(f"{where}: <origin xyz> has {len(xyz)} numbers", "give three numbers")
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    out[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                   [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                   [-sp, cp * sr, cp * cr]]
    out[:3, 3] = xyz
    return out


@dataclass(frozen=True)
class _Limit:
    lower: float | None
    upper: float | None
    velocity: float | None
    effort: float | None


@dataclass(frozen=True)
class _RawJoint:
    """The URDF semantics of one ``<joint>`` element, read directly from the sanitized XML (the same fields and
    defaults as yourdfpy, without importing it and trimesh: a third of `dgz onboard`'s wall time)."""

    name: str
    type: str | None
    parent: str | None
    child: str | None
    origin: np.ndarray
    axis: np.ndarray
    limit: _Limit | None
    damping: str | None
    mimic: tuple[str | None, float, float] | None


def _num(text) -> float | None:
    return None if text is None else float(text)  # numbers were checked finite in load_kinematics


def _raw_joints(path: Path, xml: bytes) -> list[_RawJoint]:
    root = etree.fromstring(xml, etree.XMLParser(resolve_entities=False, no_network=True))
    out = []
    for el in root.findall("joint"):
        name = el.get("name")
        if not name:
            raise UrdfError(f"{path}: not a valid URDF: a <joint> has no name", "give every <joint> a name")
        where = f"{path}: joint '{name}'"
        ends = {}
        for tag in ("parent", "child"):
            sub = el.find(tag)
            if sub is None or not sub.get("link"):
                raise UrdfError(f"{where} has no <{tag} link=...>", f"name the joint's {tag} link")
            ends[tag] = sub.get("link")
        ax = el.find("axis")
        try:
            axis = np.array([float(v) for v in ((ax.get("xyz") if ax is not None else None) or "1 0 0").split()])
        except ValueError:
            axis = np.array([math.nan] * 3)
        if axis.shape != (3,):
            axis = np.array([math.nan] * 3)
        lim = el.find("limit")
        limit = None if lim is None else _Limit(_num(lim.get("lower")), _num(lim.get("upper")),
                                                _num(lim.get("velocity")), _num(lim.get("effort")))
        dyn = el.find("dynamics")
        mim = el.find("mimic")
        mimic = None if mim is None else (mim.get("joint"), float(mim.get("multiplier", 1.0)),
                                          float(mim.get("offset", 0.0)))
        out.append(_RawJoint(name, el.get("type"), ends["parent"], ends["child"], _origin(el.find("origin"), where),
                             axis, limit, None if dyn is None else dyn.get("damping"), mimic))
    return out


def _read_joints(path: Path, xml: bytes) -> dict[str, Joint]:
    joints: dict[str, Joint] = {}
    for j in _raw_joints(path, xml):
        where = f"{path}: joint '{j.name}'"
        if j.type not in (*MOVABLE_TYPES, "fixed", "floating", "planar"):
            raise UrdfError(f"{where} has unknown type '{j.type}'", "use revolute, continuous, prismatic or fixed")
        if j.type in ("floating", "planar"):
            raise UrdfError(f"{where} is {j.type}", "a hand URDF must not contain floating/planar joints; remove it")
        origin = np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=float)
        if not np.all(np.isfinite(origin)):
            raise UrdfError(f"{where}: origin is not finite", "fix the <origin xyz rpy> values")
        axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, dtype=float)
        if j.type in MOVABLE_TYPES:
            if not np.all(np.isfinite(axis)) or np.linalg.norm(axis) < 1e-9:
                raise UrdfError(f"{where}: axis {axis.tolist()} is zero or not finite", "give a unit <axis xyz=...>")
            axis = axis / np.linalg.norm(axis)
        lim = j.limit
        lower, upper, vel, eff = -math.pi, math.pi, 0.0, 0.0
        if lim is not None:
            vel = _finite(lim.velocity or 0.0, f"{where} limit velocity", "set a finite velocity (rad/s)")
            eff = _finite(lim.effort or 0.0, f"{where} limit effort", "set a finite effort")
        if j.type in ("revolute", "prismatic"):
            if lim is None or lim.lower is None or lim.upper is None:
                raise UrdfError(f"{where} has no <limit lower upper>", "revolute/prismatic joints need limits")
            lower = _finite(lim.lower, f"{where} limit lower", "set a finite lower limit")
            upper = _finite(lim.upper, f"{where} limit upper", "set a finite upper limit")
            if lower > upper:
                raise UrdfError(f"{where}: lower limit {lower} > upper limit {upper}", "swap the limits")
        damping = 0.0
        if j.damping is not None:
            damping = _finite(j.damping, f"{where} dynamics damping", "set a finite damping")
        mimic = None
        if j.mimic is not None:
            if not j.mimic[0]:
                raise UrdfError(f"{where}: <mimic> names no joint", "write <mimic joint=\"SOURCE\" .../>")
            mimic = Mimic(j.mimic[0], j.mimic[1], j.mimic[2])
            if not (math.isfinite(mimic.multiplier) and math.isfinite(mimic.offset)):
                raise UrdfError(f"{where}: mimic multiplier/offset not finite", "fix the <mimic> element")
        joints[j.name] = Joint(j.name, j.type, j.parent, j.child, origin, axis, lower, upper, vel, eff, damping, mimic)
    for j in joints.values():
        if j.mimic is not None:
            src = joints.get(j.mimic.joint)
            if src is None or not src.movable:
                raise UrdfError(f"{path}: joint '{j.name}' mimics '{j.mimic.joint}', which is not a movable joint",
                                "point <mimic joint=...> at an existing revolute/prismatic joint")
            if src.mimic is not None:
                raise UrdfError(f"{path}: joint '{j.name}' mimics '{src.name}', which is itself a mimic joint",
                                "chain mimics to the actuated joint directly")
    return joints


def _check_tree(path: Path, links: tuple[str, ...], joints: dict[str, Joint]) -> str:
    link_set = set(links)
    parent_of: dict[str, str] = {}
    for j in joints.values():
        for end in (j.parent, j.child):
            if end not in link_set:
                raise UrdfError(f"{path}: joint '{j.name}' refers to undefined link '{end}'",
                                "define the link or fix the joint's parent/child")
        if j.child in parent_of:
            raise UrdfError(f"{path}: link '{j.child}' has two parent joints", "a URDF must be a tree")
        parent_of[j.child] = j.name
    roots = [n for n in links if n not in parent_of]
    if not roots:
        raise UrdfError(f"{path}: kinematic loop (every link has a parent)", "a URDF must be a tree; break the cycle")
    if len(roots) > 1:
        raise UrdfError(f"{path}: {len(roots)} root links ({', '.join(roots[:3])})",
                        "connect every link to one root with a joint")
    # Every link must be reachable from the root, otherwise the unreachable ones form a cycle.
    seen, stack = {roots[0]}, [roots[0]]
    while stack:
        cur = stack.pop()
        for j in joints.values():
            if j.parent == cur and j.child not in seen:
                seen.add(j.child)
                stack.append(j.child)
    if len(seen) != len(links):
        loop = sorted(link_set - seen)
        raise UrdfError(f"{path}: kinematic loop through link '{loop[0]}'", "a URDF must be a tree; break the cycle")
    return roots[0]
