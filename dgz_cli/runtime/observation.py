"""The trained policy's observation, built on hardware with the training env's own feature functions.

The layout is the policy's control contract (batch of 1, N nodes, L joints), exactly as
:meth:`dgz_cli.sim.env.GraspEnv._observe` builds it: static parts from :func:`dgz_cli.sim.scene.static_graph`,
features from :mod:`dgz_cli.sim.observe`. Where the env reads the simulator, this reads:

* θ: measured joint positions; θ̇: finite differences of successive readings (device time stamps).
* node anchors and the palm frame: forward kinematics of the hand alone (:mod:`.kinematics`).
* d and Δp: the object point cloud from ``--object-points``, fixed at the start (the paper reuses the
  first perception frame and assumes the object does not move), against the anchors moved by the
  *commanded* palm motion (the arm interface's ``palm_pose``; ``--arm none`` never moves the palm).
* wrist velocity: the commanded palm motion per control period; object velocity: 0 (static object).
* contact flags and forces: 0 — a real hand has no such sensors (privileged inputs, see ``trained.py``).
* lift flag: 1 from the first step after the grasp phase, as in the env.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dgz_cli.runtime.kinematics import HandKinematics
from dgz_cli.runtime.types import StepInput
from dgz_cli.spec.contract import ControlContract
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import HandSpec

MAX_POINTS = 4096
FORMAT_HINT = ("give a .npy array of shape (P, 3) or a text file with one 'x y z' line per point: metres, "
               "in the palm frame (origin palm centre, axes f, l, n) of the hand at its start pose")


BUILTIN_DISTANCE = 0.25  # m from the palm centre along its normal: the paper's deployment start (Supp. S2)


def builtin_object_points(name: str, n: int = 256, distance: float = BUILTIN_DISTANCE) -> np.ndarray:
    """(n, 3) surface points of a built-in primitive object (sphere, box, cylinder, capsule; the sim's
    sizes) centred ``distance`` in front of the palm (palm frame f, l, n), for dry runs without a camera."""
    import mujoco

    from dgz_cli.sim.objects import ObjectModel, object_spec, surface_points

    model = object_spec(ObjectModel(name, "primitive", None), visual=False).compile()
    pts = surface_points(model, mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "object"), n)
    return pts + np.array([0.0, 0.0, distance])


def load_object_points(path: Path) -> np.ndarray:
    """(P, 3) object surface points (m, palm frame at the start pose) from .npy or text, or a built-in
    object's name (see :func:`builtin_object_points`); at most ``MAX_POINTS`` are kept (every k-th).
    One-line errors name the file and what is wrong."""
    from dgz_cli.sim.objects import PRIMITIVES

    if str(path) in PRIMITIVES and not Path(path).exists():
        return builtin_object_points(str(path))
    path = Path(path)
    if not path.is_file():
        raise DgzError(f"{path}: no such point-cloud file (nor a built-in object: {', '.join(PRIMITIVES)})",
                       FORMAT_HINT)
    try:
        if path.suffix == ".npy":
            pts = np.load(path, allow_pickle=False)
        else:
            pts = np.loadtxt(path.read_text(encoding="utf-8").replace(",", " ").splitlines(), ndmin=2)
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        raise DgzError(f"{path}: cannot read points ({' '.join(str(exc).split())})", FORMAT_HINT) from None
    if np.asarray(pts).dtype.kind not in "fiu":
        raise DgzError(f"{path}: holds {np.asarray(pts).dtype} values, not numbers", FORMAT_HINT)
    pts = np.asarray(pts, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise DgzError(f"{path}: expected K×3 points, got shape {pts.shape}", FORMAT_HINT)
    if not np.all(np.isfinite(pts)):
        raise DgzError(f"{path}: {int(np.sum(~np.isfinite(pts)))} non-finite values", "drop NaN/inf rows")
    far = float(np.linalg.norm(pts.mean(0)))
    if far > 2.0:
        raise DgzError(f"{path}: the points' centroid is {far:.1f} m from the palm centre",
                       "the file must be in metres in the palm frame (millimetres or a camera frame?)")
    step = int(np.ceil(len(pts) / MAX_POINTS))
    return pts[::step]


def grasp_offset_of(spec: HandSpec, asset_root: str | None = None) -> np.ndarray:
    """(3,) palm centre → the open hand's node centroid, palm frame (the scripted grasp's aim point)."""
    kin = HandKinematics.for_spec(spec, asset_root)
    return kin.anchors_palm(kin.rest).mean(0)


class HardwareObservation:
    """Observation builder for a policy under ``contract`` (``reset(spec, context)`` / ``build(StepInput)``).

    ``context``: ``object_points`` (P, 3) palm frame at the start (required), ``rate_hz`` (control rate).
    """

    def __init__(self, spec: HandSpec, contract: ControlContract, asset_root: str | None = None,
                 kin: HandKinematics | None = None) -> None:
        from dgz_cli.sim import observe
        from dgz_cli.sim.scene import static_graph

        self.ob, self.spec, self.contract = observe, spec, contract
        self.kin = kin or HandKinematics.for_spec(spec, asset_root)
        g = static_graph(spec, contract.action.mode)
        n = len(spec.nodes)
        self.static = {"adjacency": g["adjacency"][None], "physical": g["physical"][None], "mask": g["mask"][None],
                       "node_valid": np.ones((1, n), bool), "closing": g["closing"][None]}
        self.static_nodes = observe.static_features(g["finger"][None], g["node_type"][None], self.static["node_valid"])
        self.proj = observe.projection(g["joint_node"], g["joint_prim"], g["joint_sign"], n)[None]  # (1, 3N, L)
        self.n = n
        lay = contract.observation
        self.grasp_offset = grasp_offset_of(spec, asset_root) if lay.has("guide") else None

    def reset(self, spec: HandSpec, context: dict) -> None:
        pts = context.get("object_points")
        if pts is None:
            raise DgzError("this policy needs the object: no --object-points given", FORMAT_HINT)
        self.cloud = np.asarray(pts, dtype=float).reshape(1, -1, 3)      # (1, P, 3) start palm frame
        self.center = self.cloud[0].mean(0)                               # (3,)
        self.dt = 1.0 / self.contract.episode.control_hz
        self.prev_q: np.ndarray | None = None
        self.prev_stamp = 0.0
        self.prev_p, self.prev_r = np.zeros(3), np.eye(3)

    def _joints(self, step: StepInput) -> tuple[np.ndarray, np.ndarray]:
        """(q (L,), q̇ (L,)): the reading, or the last one with zero velocity when this read failed."""
        s = step.state
        if s is None:
            q = self.prev_q if self.prev_q is not None else step.target
            return q, np.zeros_like(q)
        q = np.asarray(s.q, dtype=float)
        if self.prev_q is None:
            qd = np.zeros_like(q)
        else:
            dt = s.stamp - self.prev_stamp
            dt = dt if 0.5 * self.dt <= dt <= 5.0 * self.dt else self.dt  # no/odd stamps: the nominal period
            qd = (q - self.prev_q) / dt
        self.prev_q, self.prev_stamp = q, s.stamp
        return q, qd

    def build(self, step: StepInput) -> dict[str, np.ndarray]:
        ob, layout = self.ob, self.contract.observation
        q, qd = self._joints(step)
        p, r = step.palm_pose if step.palm_pose is not None else (np.zeros(3), np.eye(3))
        nodes = (p + self.kin.anchors_palm(q) @ r.T)[None]               # (1, N, 3) start palm frame
        d = ob.nearest_surface(nodes, np.zeros((1, 3)), np.eye(3)[None], self.cloud)
        rot = r[None]
        v_w = ((p - self.prev_p) / self.dt)[None]
        w_w = ob.rotation_delta(self.prev_r[None], rot) / self.dt
        self.prev_p, self.prev_r = p, r
        zeros3 = np.zeros((1, 3))
        target = ob.to_frame((self.center - p)[None], rot)
        ep = self.contract.episode
        extra_g, extra_n = {}, {}
        if layout.has("guide"):
            extra_g["guide"] = (target - self.grasp_offset[None]) / layout.target_scale
        if layout.has("phase"):
            extra_g["phase"] = np.array([step.k / ep.episode_steps])
        if layout.has("pd_error"):
            extra_n["pd_error"] = ob.pd_error(np.asarray(step.target, dtype=float)[None], q[None], self.proj,
                                              layout.pd_error_scale)
        glob = ob.global_features(layout, target=target, v_wrist=ob.to_frame(v_w, rot),
                                  w_wrist=ob.to_frame(w_w, rot), v_obj=zeros3, w_obj=zeros3,
                                  lift=np.array([step.k >= ep.grasp_steps]), **extra_g)
        none = np.zeros((1, self.n))
        x = ob.node_features(layout, self.static["node_valid"], self.static_nodes, d=ob.to_frame(d, rot),
                             theta=ob.primitive_state(q[None], self.proj), theta_dot=ob.primitive_state(qd[None], self.proj),
                             contact=none > 0, force=none, **extra_n)
        return {"nodes": x, "global": glob, **self.static}
