"""`dgz show`: the node graph and M_h as a table, and as a picture over the skeleton (--png)."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console
from rich.table import Table

from dgz_cli.spec.errors import DgzError


def run(ref: str | None, png: Path | None, asset_root: str | None, list_hands: bool, console: Console) -> int:
    from dgz_cli.spec.catalog import resolve_spec, resolve_urdf, shipped_hands
    from dgz_cli.spec.io import load_spec

    if list_hands:
        for name in shipped_hands():
            console.print(name)
        return 0
    if ref is None:
        raise DgzError("no spec given", f"name a spec file or a shipped hand ({', '.join(shipped_hands())})")
    path = resolve_spec(ref)
    spec = load_spec(path)
    from dgz_cli.viz.show import graph_table_rows

    table = Table(title=f"{spec.name} ({path}): {len(spec.nodes)} nodes, {len(spec.joints)} actuated joints, "
                        f"{spec.palm.side} hand, palm '{spec.palm.link}'")
    for col in ("node", "finger", "type", "parent", "joints (primitive, sign)", "mask"):
        table.add_column(col)
    for row in graph_table_rows(spec):
        table.add_row(*row)
    console.print(table)
    p = spec.palm
    console.print(f"palm normal n={p.normal} finger axis f={p.finger_axis} (palm link frame)")
    if png is not None:
        from dgz_cli.viz.show import render_png

        from dgz_cli.onboard.compile import Poser, compile_model
        from dgz_cli.onboard.urdf import load_kinematics

        kin = load_kinematics(resolve_urdf(spec.provenance.urdf, asset_root), spec.provenance.xacro_args)
        render_png(spec, kin, Poser(kin, compile_model(kin)), png)
        console.print(f"[green]wrote[/] {png}")
    return 0
