"""Checks of a HandSpec against its source URDF (the part of `dgz lint` that needs the file)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from dgz_cli.spec.catalog import resolve_urdf
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.lint import Finding, lint_spec
from dgz_cli.spec.models import HandSpec


_REFUSED = ("leaves ", "not a regular file", "NUL character")
MAX_URDF_BYTES = 64 * 1024 * 1024


def _sha256(path: Path, limit: int = MAX_URDF_BYTES) -> str:
    """sha256 of a file read in 1 MB chunks, at most ``limit`` bytes (a larger file is refused)."""
    h, total = hashlib.sha256(), 0
    with open(path, "rb") as fh:
        while chunk := fh.read(1 << 20):
            total += len(chunk)
            if total > limit:
                raise DgzError(f"more than the {limit >> 20} MB dgz reads", "is this the right file?")
            h.update(chunk)
    return h.hexdigest()


def verify_against_urdf(spec: HandSpec, spec_path: Path, asset_root: str | None, poser=None) -> list[Finding]:
    """``poser``: the hand already compiled from this URDF (by ``dgz onboard``), reused if it is the same file."""
    from dgz_cli.onboard.urdf import load_kinematics

    out: list[Finding] = []
    try:
        urdf = resolve_urdf(spec.provenance.urdf, asset_root)
    except DgzError as exc:
        # a name that leaves its root or names a device/FIFO/folder is an attack or a broken spec: an error;
        # a URDF that is merely absent (assets not installed here) only leaves the URDF checks undone
        refused = any(s in exc.message for s in _REFUSED)
        return [Finding("error" if refused else "warning", "provenance.urdf",
                        exc.message if refused else f"URDF not checked: {exc.message}", exc.hint)]
    reonboard = f"dgz onboard {urdf} --name {spec.name} -o {spec_path}"
    try:
        sha = _sha256(urdf)
    except (OSError, DgzError) as exc:
        return [Finding("error", "provenance.urdf", f"{urdf}: cannot be read ({getattr(exc, 'message', None) or exc})",
                        "point provenance.urdf at the hand's regular URDF file")]
    if sha != spec.provenance.urdf_sha256:
        out.append(Finding("warning", "provenance.urdf_sha256", f"{urdf} changed since this spec was written",
                           f"re-onboard: {reonboard}"))
    same = poser is not None and Path(poser.kin.source).resolve() == urdf.resolve()
    kin = poser.kin if same else load_kinematics(urdf, spec.provenance.xacro_args)
    actuated = {j.name for j in kin.actuated} - set(spec.excluded_joints)
    rows = {r.joint: (k, r) for k, r in enumerate(spec.joints)}
    for name in sorted(actuated - set(rows)):
        out.append(Finding("error", "joints", f"actuated joint '{name}' of {urdf.name} is missing from M_h",
                           f"re-onboard: {reonboard}"))
    for name in sorted(set(rows) - actuated):
        out.append(Finding("error", f"joints[{rows[name][0]}].joint",
                           f"M_h row '{name}' is not an actuated joint of {urdf.name}", f"re-onboard: {reonboard}"))
    for name, (k, r) in rows.items():
        j = kin.joints.get(name)
        if j is None or name not in actuated:
            continue
        for attr in ("lower", "upper", "velocity", "effort", "damping"):
            if abs(getattr(r, attr) - getattr(j, attr)) > 1e-5:
                out.append(Finding("error", f"joints[{k}].{attr}", f"joint '{name}': {attr} {getattr(r, attr)} "
                                   f"disagrees with the URDF ({getattr(j, attr)})", f"re-onboard: {reonboard}"))
    mimics = {m.joint: m for m in spec.mimic}
    for j in kin.joints.values():
        if j.movable and j.mimic is not None and j.name not in spec.excluded_joints:
            m = mimics.get(j.name)
            if m is None or m.source != j.mimic.joint or abs(m.multiplier - j.mimic.multiplier) > 1e-5:
                out.append(Finding("error", "mimic", f"mimic joint '{j.name}' disagrees with the URDF",
                                   f"re-onboard: {reonboard}"))
    if spec.palm.link not in kin.links:
        out.append(Finding("error", "palm.link", f"palm link '{spec.palm.link}' is not in {urdf.name}",
                           f"re-onboard: {reonboard}"))
    for k, n in enumerate(spec.nodes):
        if n.anchor_link not in kin.links:
            out.append(Finding("error", f"nodes[{k}].anchor_link", f"anchor link '{n.anchor_link}' is not in "
                               f"{urdf.name}", f"re-onboard: {reonboard}"))
    if not any(f.level == "error" for f in out):
        from dgz_cli.onboard.compile import Poser, compile_model
        from dgz_cli.onboard.functional import functional_check, rot_warnings

        poser = poser if same else Poser(kin, compile_model(kin))
        missing = _without_collision(spec, kin, poser)
        out += missing
        if missing:  # the functional check would only report its consequence ("+FLEX does not move ...")
            return out
        for problem in functional_check(spec, poser):
            out.append(Finding("error", "joints", f"functional check: {problem}",
                               "correct that finger's primitive/sign in an --overrides file, then re-onboard"))
        for problem in rot_warnings(spec, poser):
            out.append(Finding("warning", "joints", f"functional check: {problem}",
                               "look at the thumb in `dgz show`; confirm or flip its ROT sign in an --overrides file"))
    return out


def _without_collision(spec: HandSpec, kin, poser) -> list[Finding]:
    """Fingers (or the whole hand) whose links carry no collision geometry: they cannot touch anything."""
    model = poser.model

    def colliding(link: str) -> bool:
        body = poser.body.get(link)
        if body is None:
            return False
        # every geom of the onboarding model is a URDF <collision> (visuals are dropped before compiling; the
        # compile switches collisions off, compile.compile_with_warnings)
        return int(model.body_geomnum[body]) > 0

    fix = ("add <collision> geometry to those links in the URDF (the simulator grasps with collision geometry "
           "only; visual meshes are discarded)")
    if not any(colliding(link) for link in kin.links):
        return [Finding("error", "(URDF)", f"the hand has no collision geometry: none of the {len(kin.links)} links "
                        "of the URDF has a <collision> element", fix)]
    out = []
    for finger in dict.fromkeys(n.finger for n in spec.nodes if n.finger != "wrist"):
        links = {n.anchor_link for n in spec.nodes if n.finger == finger}
        links |= {kin.joints[j].child for n in spec.nodes if n.finger == finger for j in n.joints if j in kin.joints}
        if not any(colliding(link) for link in links):
            out.append(Finding("error", "nodes", f"finger '{finger}' has no collision geometry (links "
                               f"{', '.join(sorted(links))})", fix))
    return out


def lint_file(spec: HandSpec, spec_path: Path, asset_root: str | None, poser=None) -> list[Finding]:
    return lint_spec(spec) + verify_against_urdf(spec, spec_path, asset_root, poser)
