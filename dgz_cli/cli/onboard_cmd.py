"""`dgz onboard`: the pipeline plus the terminal summary."""

from __future__ import annotations

import json
import re
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from dgz_cli.spec.errors import DgzError


def default_name(urdf: Path) -> str:
    stem = urdf.name.split(".")[0].lower()
    return re.sub(r"[^a-z0-9_\-]+", "_", stem).strip("_-") or "hand"


def _same_file(a: Path, b: Path) -> bool:
    import os

    try:
        return os.path.realpath(a) == os.path.realpath(b) or os.path.samefile(a, b)
    except OSError:
        return False


def _check_output(path: Path) -> None:
    """-o must name a new or regular file (through symlinks): refused up front, with one line."""
    import os
    import stat

    try:
        st = os.stat(path)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise DgzError(f"cannot write {path}: {exc.strerror or exc}", "choose another output path") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file (a device, FIFO or socket)"
        raise DgzError(f"cannot write {path}: it exists and is {kind}", "name a new or regular file as the output")


def run(urdf: Path, out_path: Path | None, name: str | None, asset_root: str | None, palm_link: str | None,
        xacro_args: dict[str, str], overrides_file: Path | None, as_json: bool, console: Console) -> int:
    from dgz_cli.onboard.pipeline import onboard
    from dgz_cli.onboard.verify import lint_file
    from dgz_cli.spec.catalog import asset_root as resolve_root
    from dgz_cli.spec.io import load_overrides, load_spec, write_spec

    name = name or default_name(urdf)
    if not re.fullmatch(r"[a-z0-9][a-z0-9_\-]*", name):
        raise DgzError(f"--name '{name}' is not a valid hand name", "use lower-case letters, digits, '_' or '-'")
    out_path = out_path or Path(f"{name}.yaml")
    if _same_file(out_path, urdf):  # refuse before the (slow) pipeline; write_spec refuses it again
        raise DgzError(f"cannot write {out_path}: it is the input file {urdf}",
                       "write the spec to another file (e.g. -o hand.yaml)")
    _check_output(out_path)
    root = resolve_root(asset_root)
    overrides, carried = None, False
    if overrides_file is not None:
        overrides = load_overrides(overrides_file)
    elif out_path.is_file():
        try:  # a re-onboard keeps the human overrides recorded in the existing spec
            overrides, carried = load_spec(out_path).overrides, True
        except DgzError:
            overrides = None
    result = onboard(urdf, name, root, palm_link, xacro_args, overrides)
    spec = result.spec
    findings = lint_file(spec, out_path, str(root) if root else None, result.poser)
    errors = [f for f in findings if f.level == "error"]
    if not errors:
        write_spec(spec, out_path, inputs=(urdf,))
    if as_json:
        summary = dict(
            hand=spec.name, output=str(out_path) if not errors else None, lint="pass" if not errors else "fail",
            findings=[f.as_dict() for f in findings], notes=list(result.notes), palm_link=spec.palm.link, side=spec.palm.side,
            nodes=len(spec.nodes),
            joints=[dict(joint=r.joint, finger=next(n.finger for n in spec.nodes if n.id == r.node), node=r.node,
                         primitive=r.primitive.value, sign=r.sign, margin=r.margin, flagged=r.flagged)
                    for r in spec.joints])
        console.file.write(json.dumps(summary, indent=2) + "\n")
    else:
        print_summary(spec, console)
        if carried and spec.overrides.joints:
            console.print(f"[dim]kept {len(spec.overrides.joints)} override(s) from the existing "
                          f"{escape(str(out_path))}[/]")
        for note in result.notes:
            console.print(f"[dim]note: {escape(note)}[/]", soft_wrap=True)
        for f in findings:
            colour = "red" if f.level == "error" else "yellow"
            console.print(f"[{colour}]{f.level}[/] {escape(f.field)}: {escape(f.message)} [dim]— {escape(f.fix)}[/]",
                          soft_wrap=True)
        if errors:
            console.print(f"[bold red]lint failed; {escape(str(out_path))} was not written[/]")
        else:
            console.print(f"[green]wrote[/] {escape(str(out_path))} [dim](lint passed)[/]")
    return 1 if errors else 0


def print_summary(spec, console: Console) -> None:
    e = lambda s: escape(str(s))  # every name comes from the URDF: rich markup in it prints literally
    nodes = Table(title=f"{e(spec.name)}: semantic nodes ({e(spec.palm.side)} hand, palm link '{e(spec.palm.link)}')")
    for col in ("node", "finger", "type", "parent", "joints", "mask F/A/R"):
        nodes.add_column(col)
    for n in spec.nodes:
        mask = "".join(c if v else "·" for c, v in zip("FAR", spec.activation_mask[n.id]))
        nodes.add_row(e(n.id), e(n.finger), e(n.type), e(n.parent or "—"), e(", ".join(n.joints) or "—"), mask)
    console.print(nodes)
    mh = Table(title="M_h (command order): Δq = sign · α[node, primitive]")
    for col in ("#", "joint", "node", "primitive", "sign", "margin", ""):
        mh.add_column(col)
    for k, r in enumerate(spec.joints):
        flag = "[yellow]flagged[/]" if r.flagged else ("[cyan]override[/]" if r.source == "override" else "")
        mh.add_row(str(k), e(r.joint), e(r.node), r.primitive.value, f"{r.sign:+d}", f"{r.margin:.2f}", flag)
    console.print(mh)
