"""HandSpec + object → MuJoCo scene, with no hand-specific code.

The hand is compiled from its raw URDF exactly as onboarding compiles it (``spec.urdfxml``),
mounted on a 6-DoF wrist (3 slides + 3 hinges, position-controlled, gravity-compensated),
with hand-agnostic position actuators on the actuated joints (M_h order), mimic joints kept
as equality constraints, the object as a free body and a table plane at z = 0.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.sim.objects import ObjectModel, object_spec, surface_points
from dgz_cli.spec.catalog import resolve_urdf
from dgz_cli.spec.kinematics import ForwardKinematics, palm_axes, to_frame
from dgz_cli.spec.models import FINGER_CLASSES, NODE_TYPES, PRIMITIVES, HandSpec
from dgz_cli.spec.urdfxml import captured_mujoco_warnings, mujoco_xml, read_robot_xml

HAND_PREFIX = "hand/"
OBJECT_PREFIX = "obj/"
WRIST_BASE = np.array([0.0, 0.0, 0.5])  # world position of the wrist mount with the slides at 0
NOMINAL_PALM = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])  # columns f, l, n: palm facing down
WRIST_JOINTS = ("wrist_x", "wrist_y", "wrist_z", "wrist_rx", "wrist_ry", "wrist_rz")


@dataclass
class SceneIndex:
    """Addresses into one compiled scene. Shapes: L actuated joints, N nodes, P cloud points."""

    wrist_body: int
    wrist_qadr: np.ndarray  # (6,)
    hand_qadr: np.ndarray  # (L,) M_h order
    hand_dadr: np.ndarray  # (L,)
    limits: np.ndarray  # (L, 2)
    node_body: np.ndarray  # (N,)
    node_point: np.ndarray  # (N, 3) anchor in its body frame
    palm_body: int
    palm_axes: np.ndarray  # (3, 3) columns f, l, n in the palm body frame
    palm_center: np.ndarray  # (3,) palm body frame
    geom_node: np.ndarray  # (ngeom,) node index of hand geoms, -1 otherwise
    object_body: int
    object_qadr: int
    object_dadr: int
    cloud: np.ndarray  # (P, 3) object frame
    rest_q: np.ndarray  # (L,) the flat open hand: palm frame, anchors and closing axis are measured here
    start_q: np.ndarray  # (L,) the contract's start pose: every episode resets the hand to it
    palm_axes_w: np.ndarray  # (3, 3) palm frame axes (f, l, n) in the wrist mount frame, open hand
    palm_center_w: np.ndarray  # (3,) palm centre in the wrist mount frame
    grasp_offset: np.ndarray  # (3,) palm centre → the open hand's node centroid, palm frame
    closing_axis: np.ndarray  # (3,) unit, palm plane: the thumb tip → the other fingertips (l if no thumb)
    hull_g: np.ndarray  # (8G, 3) corners of the collision-geom boxes of the wrist node's bodies (palm, forearm: the
    #                     rigid part; the fingers move), wrist mount frame axes, relative to the open hand's grasp point


def _node_of_body(spec: HandSpec, model, prefix: str) -> dict[int, int]:
    """Each hand body → the node that owns it: the node of its nearest moving ancestor joint; the last
    moving link of a finger (and what is fixed to it) belongs to that finger's fingertip node."""
    import mujoco

    joint_node = {j: i for i, n in enumerate(spec.nodes) for j in n.joints}
    tip_node = {n.anchor_link: i for i, n in enumerate(spec.nodes) if n.type == "fingertip"}
    wrist = next(i for i, n in enumerate(spec.nodes) if n.type == "wrist")
    out = {}
    for b in range(model.nbody):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or ""
        if not name.startswith(prefix):
            continue
        cur, node = b, wrist
        while cur > 0:
            link = (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, cur) or "")[len(prefix):]
            if link in tip_node:
                node = tip_node[link]
                break
            jnt = model.body_jntadr[cur]
            if model.body_jntnum[cur] > 0:
                jname = (mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, jnt) or "")[len(prefix):]
                if jname in joint_node:
                    node = joint_node[jname]
                    break
            cur = model.body_parentid[cur]
        out[b] = node
    return out


def palm_in_root(spec: HandSpec, hand) -> tuple[np.ndarray, np.ndarray]:
    """Palm frame axes (3, 3; columns f, l, n) and palm centre (3,) in the frame the hand is attached by
    (the hand model's world frame; a URDF link named ``world`` is that frame), open hand."""
    with captured_mujoco_warnings():
        model = hand.compile()
    fk = ForwardKinematics(model, [r.joint for r in spec.joints], spec.mimic)
    fk.pose(spec.rest_pose())
    return fk.palm_frame(spec.palm)


@functools.lru_cache(maxsize=16)
def _hand_xml_and_palm(spec_json: str, urdf: str, mtime_ns: int) -> tuple[str, np.ndarray, np.ndarray]:
    """The hand's MuJoCo XML and its palm frame in the root frame, once per (spec, URDF): an env with
    many objects builds one scene per (hand, object) and would otherwise parse the URDF and compile
    the hand alone for each. ``mtime_ns`` keys an edited URDF apart. The arrays are read-only (shared
    by the cache)."""
    import mujoco

    spec = HandSpec.model_validate_json(spec_json)
    robot = read_robot_xml(Path(urdf), spec.provenance.xacro_args)
    xml = mujoco_xml(robot)
    axes, center = palm_in_root(spec, mujoco.MjSpec.from_string(xml))
    axes.setflags(write=False)
    center.setflags(write=False)
    return xml, axes, center


def build_spec(spec: HandSpec, obj: ObjectModel, cfg: EnvConfig, asset_root: str | None, visual: bool = False):
    """The scene as an ``MjSpec`` (call ``.compile()``; ``.to_xml()`` for a standalone file)."""
    import mujoco

    urdf = resolve_urdf(spec.provenance.urdf, asset_root)
    hand_xml, palm_axes_w, palm_center_w = _hand_xml_and_palm(spec.model_dump_json(), str(urdf),
                                                                   urdf.stat().st_mtime_ns)
    hand = mujoco.MjSpec.from_string(hand_xml)
    mount = NOMINAL_PALM @ palm_axes_w.T  # palm down, finger axis along world +x
    world = mujoco.MjSpec()
    world.modelname = f"dgz_{spec.name}_{obj.name}"
    world.option.timestep = cfg.contract.episode.physics_dt
    world.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    world.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC  # elliptic cones + high impratio: grasps slip less
    world.option.impratio = cfg.impratio
    world.compiler.degree = False
    world.worldbody.add_light(pos=[0, 0, 1.5], dir=[0, 0, -1], diffuse=[0.8, 0.8, 0.8])
    world.worldbody.add_geom(name="table", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.05],
                             rgba=[0.6, 0.6, 0.65, 1], friction=[1.0, 0.005, 0.0001])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mount.reshape(-1))
    wrist = world.worldbody.add_body(name="wrist", pos=list(WRIST_BASE), quat=list(quat), gravcomp=1.0)
    wrist.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0], mass=0.2, contype=0, conaffinity=0,
                   rgba=[0.2, 0.2, 0.2, 1])
    # slides along the world axes; hinges about the palm frame's f, l, n axes (small tilts, any roll about n)
    axes = list(mount) + list(palm_axes_w.T)  # rows of mount = world axes in the mount frame
    for k, name in enumerate(WRIST_JOINTS):
        jtype = mujoco.mjtJoint.mjJNT_SLIDE if k < 3 else mujoco.mjtJoint.mjJNT_HINGE
        wrist.add_joint(name=name, type=jtype, axis=list(axes[k]), armature=0.01, damping=0.0)
    frame = wrist.add_frame()
    world.attach(hand, frame=frame, prefix=HAND_PREFIX)
    for b in world.bodies:
        if b.name.startswith(HAND_PREFIX):
            b.gravcomp = 1.0
    rows = {r.joint: r for r in spec.joints}
    for j in world.joints:
        if j.name.startswith(HAND_PREFIX):
            j.armature = max(j.armature, cfg.joint_armature)
            # MuJoCo's URDF import also clamps the joint's summed actuator force at the URDF effort; the
            # actuator's forcerange (the spec's effort, below) is the one home of that limit, so that scaling
            # it (Slot.set_dynamics) acts in both directions
            j.actfrclimited = mujoco.mjtLimited.mjLIMITED_FALSE
    for k, name in enumerate(WRIST_JOINTS):
        kp = cfg.wrist_kp_lin if k < 3 else cfg.wrist_kp_ang
        _position_actuator(world, name, kp, None)
    for r in spec.joints:
        _position_actuator(world, HAND_PREFIX + r.joint, cfg.finger_kp, rows[r.joint].effort or None)
    world.attach(object_spec(obj, visual), frame=world.worldbody.add_frame(), prefix=OBJECT_PREFIX)
    return world


def _position_actuator(world, joint: str, kp: float, effort: float | None) -> None:
    import mujoco

    act = world.add_actuator(name=joint, target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.set_to_position(kp=kp, dampratio=1.0)
    if effort is not None and effort > 0:
        act.forcelimited = True
        act.forcerange = [-effort, effort]


def build_scene(spec: HandSpec, obj: ObjectModel, cfg: EnvConfig, asset_root: str | None = None, seed: int = 0):
    """Compile the scene; returns (MjModel, SceneIndex, compiler warnings)."""
    import mujoco

    s = build_spec(spec, obj, cfg, asset_root)
    with captured_mujoco_warnings() as warnings:
        model = s.compile()
    return model, index_scene(spec, model, cfg, seed), list(warnings)


def index_scene(spec: HandSpec, model, cfg: EnvConfig, seed: int = 0) -> SceneIndex:
    import mujoco

    def jid(name: str) -> int:
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)

    def bid(name: str) -> int:
        return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)

    hand_j = [jid(HAND_PREFIX + r.joint) for r in spec.joints]
    # the open hand in the wrist mount's frame (wrist joints at 0): palm frame and node anchors. Mimic
    # joints stay at 0 here (not at their offsets), as every scene and policy so far was built with.
    fk = ForwardKinematics(model, [r.joint for r in spec.joints], prefix=HAND_PREFIX)
    node_body = np.array([fk.body(n.anchor_link) for n in spec.nodes])
    node_point = np.array([n.anchor_point for n in spec.nodes], dtype=float)
    palm = fk.body(spec.palm.link)
    owner = _node_of_body(spec, model, HAND_PREFIX)
    geom_node = np.array([owner.get(int(model.geom_bodyid[g]), -1) for g in range(model.ngeom)])
    obj_body = bid(OBJECT_PREFIX + "object")
    obj_j = model.body_jntadr[obj_body]
    rest_q = spec.rest_pose()
    fk.pose(rest_q)
    wrist = bid("wrist")
    palm_axes_w, palm_center_w = fk.palm_frame(spec.palm, base=wrist)
    anchors = to_frame(fk.points(node_body, node_point), *fk.frame(wrist))
    start_q = cfg.contract.start.pose(spec)
    fk.pose(start_q)
    wrist_node = next(i for i, n in enumerate(spec.nodes) if n.type == "wrist")
    hull_g = to_frame(_geom_box_corners(model, fk.data, geom_node == wrist_node), *fk.frame(wrist)) - anchors.mean(0)
    return SceneIndex(
        wrist_body=wrist,
        wrist_qadr=np.array([model.jnt_qposadr[jid(n)] for n in WRIST_JOINTS]),
        hand_qadr=np.array([model.jnt_qposadr[j] for j in hand_j]),
        hand_dadr=np.array([model.jnt_dofadr[j] for j in hand_j]),
        limits=np.array([[r.lower, r.upper] for r in spec.joints]),
        node_body=node_body,
        node_point=node_point,
        palm_body=palm,
        palm_axes=palm_axes(spec.palm),
        palm_center=np.array(spec.palm.center, dtype=float),
        geom_node=geom_node,
        object_body=obj_body,
        object_qadr=int(model.jnt_qposadr[obj_j]),
        object_dadr=int(model.jnt_dofadr[obj_j]),
        cloud=surface_points(model, obj_body, cfg.contract.observation.point_cloud, seed),
        rest_q=rest_q,
        start_q=start_q,
        palm_axes_w=palm_axes_w,
        palm_center_w=palm_center_w,
        grasp_offset=palm_axes_w.T @ (anchors.mean(0) - palm_center_w),
        closing_axis=closing_axis(spec, (anchors - palm_center_w) @ palm_axes_w),
        hull_g=hull_g,
    )


def _geom_box_corners(model, data, hand: np.ndarray) -> np.ndarray:
    """(8G, 3) world corners of the bounding boxes (``geom_aabb``, geom frame) of the G colliding geoms selected
    by ``hand`` (ngeom,) bool, at ``data``'s current kinematics."""
    sel = np.nonzero(hand & ((model.geom_contype != 0) | (model.geom_conaffinity != 0)))[0]
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    aabb = model.geom_aabb[sel]  # (G, 6): centre, half-sizes
    local = aabb[:, None, :3] + signs[None] * aabb[:, None, 3:]  # (G, 8, 3)
    rot = data.geom_xmat[sel].reshape(-1, 3, 3)
    return (data.geom_xpos[sel][:, None] + np.einsum("gij,gkj->gki", rot, local)).reshape(-1, 3)


def closing_axis(spec: HandSpec, anchors_palm: np.ndarray) -> np.ndarray:
    """(3,) unit vector in the palm plane (n component 0) along which the open hand closes: from the thumb's
    fingertip to the mean of the other fingertips; the lateral axis l when there is no thumb or no other
    finger. ``anchors_palm`` (N, 3): node anchors in the palm frame."""
    tips = [i for i, n in enumerate(spec.nodes) if n.type == "fingertip"]
    thumb = [i for i in tips if spec.nodes[i].finger == "thumb"]
    others = [i for i in tips if spec.nodes[i].finger != "thumb"]
    if thumb and others:
        v = anchors_palm[others].mean(0) - anchors_palm[thumb].mean(0)
        v[2] = 0.0
        if np.linalg.norm(v) > 1e-6:
            return v / np.linalg.norm(v)
    return np.array([0.0, 1.0, 0.0])


def static_graph(spec: HandSpec, mode: str = "primitive") -> dict[str, np.ndarray]:
    """Per-hand constants for the policy: adjacency (N, N), physical features (N, 27), mask (N, 3),
    one-hot finger class (N, 6) and node type (N, 6), the M_h gather arrays (L,) with each joint's slot
    among its node's joints, and ``closing`` (N, 3): the direction each node action moves to close the hand.

    ``mode`` is the contract's action mode. ``primitive``: ``mask`` is the spec's activation mask and
    ``closing`` is +1 on the FLEX column of FLEX-active nodes. ``joint`` (raw joint increments, the
    w/o-primitives ablation): a node's 3 action values drive its joints in M_h order, so ``mask`` marks the
    slots that drive a joint and ``closing`` holds the sign of each FLEX joint in its slot (0 elsewhere)."""
    ids = {n.id: i for i, n in enumerate(spec.nodes)}
    n = len(spec.nodes)
    adj = np.zeros((n, n), dtype=np.float32)
    for i, node in enumerate(spec.nodes):
        if node.parent is not None:
            adj[ids[node.parent], i] = 1.0
    joint_node = np.array([ids[r.node] for r in spec.joints], dtype=np.int64)
    joint_prim = np.array([PRIMITIVES.index(r.primitive.value) for r in spec.joints], dtype=np.int64)
    joint_sign = np.array([r.sign for r in spec.joints], dtype=np.float64)
    joint_slot = spec.joint_slots()
    activation = np.array([spec.activation_mask[x.id] for x in spec.nodes], dtype=np.float32)
    flex = PRIMITIVES.index("FLEX")
    closing = np.zeros((n, len(PRIMITIVES)), dtype=np.float32)
    if mode == "joint":
        if joint_slot.size and joint_slot.max() >= len(PRIMITIVES):
            from dgz_cli.spec.errors import DgzError

            raise DgzError(f"hand '{spec.name}': a node drives {joint_slot.max() + 1} joints; the joint action mode "
                           f"(--ablation no_primitives) has {len(PRIMITIVES)} values per node",
                           "train this hand with primitive actions (any other --ablation)")
        mask = np.zeros_like(closing)
        mask[joint_node, joint_slot] = 1.0
        closing[joint_node, joint_slot] = np.where(joint_prim == flex, joint_sign, 0.0)
    else:
        mask = activation
        closing[:, flex] = activation[:, flex] > 0
    return dict(
        adjacency=adj,
        physical=np.array([spec.features.values[x.id] for x in spec.nodes], dtype=np.float32),
        mask=mask,
        closing=closing,
        finger=np.eye(len(FINGER_CLASSES), dtype=np.float32)[[FINGER_CLASSES.index(x.finger) for x in spec.nodes]],
        node_type=np.eye(len(NODE_TYPES), dtype=np.float32)[[NODE_TYPES.index(x.type) for x in spec.nodes]],
        joint_node=joint_node, joint_prim=joint_prim, joint_sign=joint_sign, joint_slot=joint_slot,
    )


def write_scene_xml(spec: HandSpec, obj: ObjectModel, cfg: EnvConfig, asset_root: str | None, out: Path) -> None:
    """A standalone MJCF that opens in MuJoCo's viewer (`python -m mujoco.viewer --mjcf FILE`)."""
    from dgz_cli.spec.io import atomic_write

    s = build_spec(spec, obj, cfg, asset_root, visual=True)
    with captured_mujoco_warnings():
        s.compile()  # an invalid scene fails here, before anything is written
    atomic_write(out, s.to_xml())
