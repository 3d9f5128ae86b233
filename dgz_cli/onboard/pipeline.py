"""URDF/xacro → HandSpec: the whole `dgz onboard` pipeline, minus the terminal."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dgz_cli import __version__
from dgz_cli.onboard import excite, frame, nodes, structure
from dgz_cli.onboard.compile import Poser, compile_with_warnings
from dgz_cli.onboard.features import NORMALIZATION, activation_mask, node_features
from dgz_cli.onboard.urdf import load_kinematics
from dgz_cli.spec.catalog import urdf_reference
from dgz_cli.spec.errors import OnboardError
from dgz_cli.spec.models import FEATURE_NAMES, HandSpec, Overrides

FINGER_ORDER = ("thumb", "index", "middle", "ring", "little")


@dataclass(frozen=True)
class OnboardResult:
    spec: HandSpec
    responses: dict[str, excite.Response]
    notes: tuple[str, ...] = ()  # MuJoCo compiler warnings and similar, for the user to read
    poser: Poser | None = None  # the compiled hand, so the lint that follows need not compile it again


def _r(v, nd: int = 6) -> list[float]:
    return [round(float(x), nd) + 0.0 for x in v]


def onboard(urdf: Path, name: str, asset_root: Path | None = None, palm_link: str | None = None,
            xacro_args: dict[str, str] | None = None, overrides: Overrides | None = None,
            settings: excite.ExcitationSettings = excite.ExcitationSettings()) -> OnboardResult:
    overrides = overrides or Overrides()
    kin = load_kinematics(urdf, xacro_args)
    model, mj_warnings = compile_with_warnings(kin)
    poser = Poser(kin, model)
    st = structure.analyse(kin, poser, palm_link)
    fr = frame.estimate(kin, poser, st)
    responses = excite.Exciter(kin, poser, st, fr, settings).run()
    where = str(urdf)

    movable = set(responses)
    for jname in overrides.joints:
        if jname not in movable:
            raise OnboardError(f"overrides: joint '{jname}' is not a movable joint of {urdf}",
                               "fix the joint name in the overrides file")
    primitive = {j: (overrides.joints[j].primitive.value if j in overrides.joints and overrides.joints[j].primitive
                     else r.primitive) for j, r in responses.items()}

    # ---- semantic nodes -------------------------------------------------------------------------
    poser.pose(poser.rest())
    palm_rot, palm_pos = poser.link_rot(st.palm_link), poser.link_pos(st.palm_link)
    node_rows: list[dict] = [dict(id="wrist", finger="wrist", type="wrist", parent=None,
                                  joints=list(st.wrist_joints) + list(st.shared_joints), anchor_link=st.palm_link,
                                  anchor_point=_r(palm_rot.T @ (fr.center - palm_pos)), pos=fr.center)]
    order = sorted(range(len(st.chains)), key=lambda i: FINGER_ORDER.index(fr.fingers[i]))
    for i in order:
        chain, cls = st.chains[i], fr.fingers[i]
        groups = nodes.group_chain(chain.joints, primitive, poser, where)
        parent = "wrist"
        for group, typ in zip(groups, nodes.TYPES_BY_COUNT[len(groups)]):
            first = kin.joints[group[0]]
            nid = f"{cls}_{typ}"
            node_rows.append(dict(id=nid, finger=cls, type=typ, parent=parent, joints=group,
                                  anchor_link=first.child, anchor_point=[0.0, 0.0, 0.0],
                                  pos=poser.joint_anchor(group[0])))
            parent = nid
        node_rows.append(dict(id=f"{cls}_tip", finger=cls, type="fingertip", parent=parent, joints=[],
                              anchor_link=chain.tip_link, anchor_point=_r(chain.tip_point),
                              pos=poser.link_pos(chain.tip_link, chain.tip_point)))
    node_of = {j: n["id"] for n in node_rows for j in n["joints"]}
    for jname, ov in overrides.joints.items():
        if ov.node is not None and ov.node != node_of.get(jname):
            target = next((n for n in node_rows if n["id"] == ov.node), None)
            if target is None or target["type"] == "fingertip" or len(target["joints"]) >= 3:
                raise OnboardError(f"overrides: joint '{jname}' cannot move to node '{ov.node}'",
                                   "name an existing non-fingertip node with fewer than 3 joints")
            for n in node_rows:
                if jname in n["joints"]:
                    n["joints"].remove(jname)
            target["joints"].append(jname)
            node_of[jname] = ov.node

    # ---- M_h ------------------------------------------------------------------------------------
    actuated = [j.name for j in kin.actuated if j.name not in st.excluded_joints]
    command = list(overrides.command_order) if overrides.command_order else actuated
    if sorted(command) != sorted(actuated):
        unknown = [j for j in command if j not in actuated]
        missing = [j for j in actuated if j not in command]
        twice = sorted({j for j in command if command.count(j) > 1})
        what = (f"names '{unknown[0]}', which is not an actuated joint of the URDF" if unknown else
                f"lists '{twice[0]}' more than once" if twice else f"does not list '{missing[0]}'")
        raise OnboardError(f"overrides: command_order {what}", "list each actuated joint of the URDF exactly once "
                           f"(actuated: {', '.join(actuated[:8])}{', ...' if len(actuated) > 8 else ''})")
    rows = []
    for jname in command:
        j, r = kin.joints[jname], responses[jname]
        ov = overrides.joints.get(jname)
        sign = ov.sign if ov is not None and ov.sign is not None else r.sign
        overridden = ov is not None and (primitive[jname] != r.primitive or sign != r.sign
                                         or (ov.node is not None))
        rows.append(dict(joint=jname, node=node_of[jname], primitive=primitive[jname], sign=int(sign),
                         lower=round(j.lower, 6), upper=round(j.upper, 6), velocity=round(j.velocity, 6),
                         effort=round(j.effort, 6), damping=round(j.damping, 6), margin=min(1.0, r.margin),
                         flagged=bool(r.flagged and not overridden),
                         source="override" if overridden else "identified",
                         identified_primitive=r.primitive if overridden else None,
                         identified_sign=r.sign if overridden else None))

    # ---- features -------------------------------------------------------------------------------
    to_palm = fr.to_palm
    axes = {jname: to_palm(poser.joint_axis(jname)) for jname in command}
    pos = {n["id"]: n["pos"] for n in node_rows}
    feats = {}
    for n in node_rows:
        link_vec = to_palm(pos[n["id"]] - pos[n["parent"]]) if n["parent"] else np.zeros(3)
        feats[n["id"]] = node_features([r for r in rows if r["node"] == n["id"]], axes, link_vec)

    mimic = [dict(joint=j.name, source=j.mimic.joint, multiplier=round(j.mimic.multiplier, 6),
                  offset=round(j.mimic.offset, 6), node=node_of.get(j.name))
             for j in kin.joints.values() if j.movable and j.mimic is not None and j.name not in st.excluded_joints]

    spec = HandSpec.model_validate(dict(
        name=name,
        provenance=dict(urdf=urdf_reference(urdf, asset_root), urdf_sha256=kin.sha256,
                        upstream=overrides.upstream, upstream_commit=overrides.upstream_commit,
                        xacro_args=dict(xacro_args or {}), dgz_version=__version__,
                        excitation=dict(delta=settings.delta, flexed_fraction=settings.flexed_fraction,
                                        margin_threshold=settings.margin_threshold)),
        palm=dict(link=st.palm_link, normal=_r(palm_rot.T @ fr.normal), finger_axis=_r(palm_rot.T @ fr.finger_axis),
                  lateral=_r(palm_rot.T @ fr.lateral), center=_r(palm_rot.T @ (fr.center - palm_pos)), side=fr.side),
        nodes=[{k: v for k, v in n.items() if k != "pos"} for n in node_rows],
        joints=rows,
        mimic=mimic,
        excluded_joints=list(st.excluded_joints),
        activation_mask=activation_mask([n["id"] for n in node_rows], rows),
        features=dict(names=FEATURE_NAMES, normalization=NORMALIZATION.model_dump(), values=feats),
        overrides=overrides.model_dump(exclude_defaults=True),
    ))
    notes = tuple(f"MuJoCo: {w}" for w in mj_warnings)
    notes += tuple(f"joint '{r.joint}' → {r.primitive} ({r.note}; margin {r.margin:.2f}): check it with `dgz show`"
                   for r in responses.values() if r.flagged and r.joint in command)
    return OnboardResult(spec, responses, notes, poser)
