"""Checks of a HandSpec against its source URDF (the part of `dgz lint` that needs the file)."""

from __future__ import annotations

import hashlib
from pathlib import Path

from dgz_cli.spec.catalog import resolve_urdf
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.lint import Finding, lint_spec
from dgz_cli.spec.models import HandSpec


def verify_against_urdf(spec: HandSpec, spec_path: Path, asset_root: str | None, poser=None) -> list[Finding]:
    """``poser``: the hand already compiled from this URDF (by ``dgz onboard``), reused if it is the same file."""
    from dgz_cli.onboard.urdf import load_kinematics

    out: list[Finding] = []
    try:
        urdf = resolve_urdf(spec.provenance.urdf, asset_root)
    except DgzError as exc:
        return [Finding("warning", "provenance.urdf", f"URDF not checked: {exc.message}", exc.hint)]
    reonboard = f"dgz onboard {urdf} --name {spec.name} -o {spec_path}"
    sha = hashlib.sha256(urdf.read_bytes()).hexdigest()
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
        from dgz_cli.onboard.functional import functional_check

        for problem in functional_check(spec, poser if same else Poser(kin, compile_model(kin))):
            out.append(Finding("error", "joints", f"functional check: {problem}",
                               "correct that finger's primitive/sign in an --overrides file, then re-onboard"))
    return out


def lint_file(spec: HandSpec, spec_path: Path, asset_root: str | None, poser=None) -> list[Finding]:
    return lint_spec(spec) + verify_against_urdf(spec, spec_path, asset_root, poser)
