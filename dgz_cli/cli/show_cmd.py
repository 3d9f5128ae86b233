"""`dgz show`: the node graph and M_h as a table, and as a picture over the skeleton (--png)."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from dgz_cli.spec.errors import DgzError


def run(ref: str | None, png: Path | None, asset_root: str | None, list_hands: bool, console: Console) -> int:
    from dgz_cli.spec.catalog import resolve_spec, resolve_urdf, shipped_hands
    from dgz_cli.spec.io import load_spec

    if list_hands:
        for name in shipped_hands():
            console.print(escape(name))
        return 0
    if ref is None:
        raise DgzError("no spec given", f"name a spec file or a shipped hand ({', '.join(shipped_hands())})")
    path = resolve_spec(ref)
    spec = load_spec(path)
    from dgz_cli.viz.show import graph_table_rows

    # every name below comes from the spec file: escaped, so rich markup in a name prints literally
    table = Table(title=f"{escape(spec.name)} ({escape(str(path))}): {len(spec.nodes)} nodes, {len(spec.joints)} "
                        f"actuated joints, {escape(spec.palm.side)} hand, palm '{escape(spec.palm.link)}'")
    for col in ("node", "finger", "type", "parent", "joints (primitive, sign)", "mask"):
        table.add_column(col)
    for row in graph_table_rows(spec):
        table.add_row(*(escape(str(c)) for c in row))
    console.print(table)
    p = spec.palm
    console.print(escape(f"palm normal n={p.normal} finger axis f={p.finger_axis} (palm link frame)"))
    if png is not None:
        from dgz_cli.viz.show import render_png

        from dgz_cli.onboard.compile import Poser, compile_model
        from dgz_cli.onboard.urdf import load_kinematics

        kin = load_kinematics(resolve_urdf(spec.provenance.urdf, asset_root), spec.provenance.xacro_args)
        render_png(spec, kin, Poser(kin, compile_model(kin)), png)
        console.print(f"[green]wrote[/] {escape(str(png))}")
    return 0
