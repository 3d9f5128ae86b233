"""Forward kinematics of a hand: the one implementation onboarding, simulation, hardware and runtime call.

* :func:`rest_pose`: the rest pose, every joint at 0 clipped into its limits (the flat open hand on the
  shipped hands); :meth:`HandSpec.rest_pose` applies it to a spec.
* :class:`ForwardKinematics`: any compiled MuJoCo model that holds the hand (alone, or inside a training
  scene with its names prefixed). Only ``mj_kinematics`` runs: the driven joints take the given values and
  every mimic joint follows its source (``q = multiplier · q_source + offset``, clipped to the joint's range
  when MuJoCo limits it), as the equality constraints of a simulated hand hold it.
* :class:`HandKinematics`: a spec's hand compiled alone, in the spec's joint order: palm frame, node
  anchors and fingertips, expressed in the palm frame (origin ``spec.palm.center``, axes f, l, n).

MuJoCo is imported inside the functions that need it: :mod:`dgz_cli.spec` stays light to import.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import numpy as np

from dgz_cli.spec.errors import UrdfError
from dgz_cli.spec.models import rest_pose

if TYPE_CHECKING:
    from dgz_cli.spec.models import HandSpec, MimicJoint, Palm

_CACHE: dict[tuple, "HandKinematics"] = {}


def palm_axes(palm: Palm) -> np.ndarray:
    """(3, 3) palm frame axes in the palm link's frame, columns f, l, n."""
    return np.stack([palm.finger_axis, palm.lateral, palm.normal], axis=1)


def to_frame(points: np.ndarray, axes: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """Points (..., 3) → coordinates in the frame with ``axes`` (3, 3; columns) and ``origin`` (3,)."""
    return (points - origin) @ axes


def hand_xml(spec: HandSpec, asset_root: str | None = None) -> str:
    """The spec's URDF, sanitized, with dgz's MuJoCo compiler settings injected (what every layer compiles)."""
    from dgz_cli.spec.catalog import resolve_urdf
    from dgz_cli.spec.urdfxml import mujoco_xml, read_robot_xml

    return mujoco_xml(read_robot_xml(resolve_urdf(spec.provenance.urdf, asset_root), spec.provenance.xacro_args))


def compile_hand(spec: HandSpec, asset_root: str | None = None):
    """The spec's hand alone as an ``MjModel``, fixed to the world at its root link."""
    import mujoco

    from dgz_cli.spec.urdfxml import captured_mujoco_warnings

    with captured_mujoco_warnings():
        try:
            return mujoco.MjSpec.from_string(hand_xml(spec, asset_root)).compile()
        except ValueError as exc:
            raise UrdfError(f"{spec.provenance.urdf}: MuJoCo cannot compile it: {' '.join(str(exc).split())}",
                            f"run `dgz lint {spec.name}` to find the broken element") from None


class ForwardKinematics:
    """Forward kinematics of the hand in a compiled ``model`` (names of hand joints and links carry
    ``prefix``). ``joints`` (L,) are the driven joints, in the order of the values :meth:`pose` takes;
    ``mimic`` rows (``joint``, ``source``, ``multiplier``, ``offset``) name a driven joint as source.
    Positions are in the model's world frame (m)."""

    def __init__(self, model, joints: Sequence[str], mimic: Sequence[MimicJoint] = (), prefix: str = "") -> None:
        import mujoco

        self._mj = mujoco
        self.model, self.data, self.prefix = model, mujoco.MjData(model), prefix
        self.qadr = np.array([self.joint_qadr(j) for j in joints], dtype=int)  # (L,)
        index = {j: i for i, j in enumerate(joints)}
        self.mimic = []  # (qpos address, source index, multiplier, offset, lower, upper)
        for m in mimic:
            if m.source not in index:
                raise UrdfError(f"mimic joint '{m.joint}' follows '{m.source}', which is not driven",
                                "a mimic joint must follow an actuated joint")
            jid = self.joint_id(m.joint)
            lo, hi = model.jnt_range[jid] if model.jnt_limited[jid] else (-np.inf, np.inf)
            self.mimic.append((int(model.jnt_qposadr[jid]), index[m.source], m.multiplier, m.offset, lo, hi))

    def joint_id(self, name: str) -> int:
        jid = self._mj.mj_name2id(self.model, self._mj.mjtObj.mjOBJ_JOINT, self.prefix + name)
        if jid < 0:
            raise UrdfError(f"joint '{name}' is not in the compiled hand",
                            "the spec and the URDF disagree: re-onboard the hand")
        return jid

    def joint_qadr(self, name: str) -> int:
        """qpos address of hand joint ``name``."""
        return int(self.model.jnt_qposadr[self.joint_id(name)])

    def body(self, link: str) -> int:
        """Body id of hand link ``link``; 0 (the world body) for a link MuJoCo merged into it (the root)."""
        return max(0, self._mj.mj_name2id(self.model, self._mj.mjtObj.mjOBJ_BODY, self.prefix + link))

    def pose(self, q: np.ndarray, extra: dict[str, float] | None = None) -> None:
        """Driven joints to ``q`` (L,), mimics follow, then ``extra`` offsets (joint name → Δq) on any hand
        joint; every other joint at its reference value. Runs ``mj_kinematics``."""
        d = self.data
        d.qpos[:] = self.model.qpos0
        q = np.asarray(q, dtype=float)
        d.qpos[self.qadr] = q
        for adr, src, mult, off, lo, hi in self.mimic:
            d.qpos[adr] = np.clip(mult * q[src] + off, lo, hi)
        for name, dq in (extra or {}).items():
            d.qpos[self.joint_qadr(name)] += dq
        self._mj.mj_kinematics(self.model, d)

    def value(self, name: str) -> float:
        """Value of hand joint ``name`` at the current pose."""
        return float(self.data.qpos[self.joint_qadr(name)])

    def points(self, bodies: np.ndarray, local: np.ndarray) -> np.ndarray:
        """World positions (N, 3) of points ``local`` (N, 3) given in the frames of ``bodies`` (N,)."""
        d = self.data
        return d.xpos[bodies] + np.einsum("nij,nj->ni", d.xmat[bodies].reshape(-1, 3, 3), local)

    def frame(self, body: int) -> tuple[np.ndarray, np.ndarray]:
        """Rotation (3, 3) and origin (3,) of ``body`` in the world frame, at the current pose."""
        return self.data.xmat[body].reshape(3, 3), self.data.xpos[body]

    def palm_frame(self, palm: Palm, base: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Palm axes (3, 3; columns f, l, n) and centre (3,) in body ``base``'s frame (0: the world),
        at the current pose."""
        r_b, p_b = self.frame(base)
        r_p, p_p = self.frame(self.body(palm.link))
        return r_b.T @ r_p @ palm_axes(palm), r_b.T @ (r_p @ np.array(palm.center, dtype=float) + p_p - p_b)


class HandKinematics:
    """A spec's hand compiled alone (its root link fixed to the world: the *root frame*), driven by the
    spec's actuated joints in ``spec.joints`` order, mimics from ``spec.mimic``."""

    def __init__(self, spec: HandSpec, asset_root: str | None = None) -> None:
        self.spec = spec
        self.fk = ForwardKinematics(compile_hand(spec, asset_root), [r.joint for r in spec.joints], spec.mimic)
        self.node_body = np.array([self.fk.body(n.anchor_link) for n in spec.nodes])  # (N,)
        self.node_point = np.array([n.anchor_point for n in spec.nodes], dtype=float)  # (N, 3) body frames
        self.rest = spec.rest_pose()  # (L,)

    @classmethod
    def for_spec(cls, spec: HandSpec, asset_root: str | None = None) -> HandKinematics:
        """One compiled model per (spec, URDF hash, asset root) and process."""
        key = (spec.name, spec.provenance.urdf, spec.provenance.urdf_sha256, asset_root)
        if key not in _CACHE:
            _CACHE[key] = cls(spec, asset_root)
        return _CACHE[key]

    def pose(self, q: np.ndarray) -> None:
        """Set the actuated joints (L,) rad, spec order; mimics follow; run kinematics."""
        self.fk.pose(q)

    def palm_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """Palm axes (3, 3; columns f, l, n) and centre (3,) in the root frame, at the current pose."""
        return self.fk.palm_frame(self.spec.palm)

    def anchors_root(self) -> np.ndarray:
        """(N, 3) node anchor points in the root frame, at the current pose."""
        return self.fk.points(self.node_body, self.node_point)

    def anchors_palm(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) node anchor points in the palm frame for joint values ``q`` (L,)."""
        self.pose(q)
        return to_frame(self.anchors_root(), *self.palm_frame())
