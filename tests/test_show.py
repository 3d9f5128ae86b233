"""dgz_cli.viz.show: the graph-over-skeleton figure and the node table."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from dgz_cli.spec.models import PRIMITIVES
from dgz_cli.viz.show import graph_table_rows, render_png


@pytest.fixture(scope="module")
def allegro():
    root = os.environ.get("DGZ_ASSET_ROOT")
    if not root:
        pytest.skip("DGZ_ASSET_ROOT not set: vendor assets unavailable")
    from dgz_cli.onboard.pipeline import onboard

    urdf = Path(root) / "hands/allegro/urdf/allegro_hand_right.urdf"
    return onboard(urdf, "allegro", asset_root=Path(root)).spec, urdf


def test_render_png_writes_a_readable_figure(allegro, tmp_path):
    import matplotlib.image

    spec, urdf = allegro
    out = tmp_path / "figs" / "a.png"  # parent directories are created
    from dgz_cli.onboard.compile import Poser, compile_model
    from dgz_cli.onboard.urdf import load_kinematics

    kin = load_kinematics(urdf, spec.provenance.xacro_args)
    render_png(spec, kin, Poser(kin, compile_model(kin)), out)
    assert out.is_file()
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = matplotlib.image.imread(out)
    assert img.ndim == 3 and img.shape[0] > 400 and img.shape[1] > 800
    rgba = (img.reshape(-1, img.shape[2]) * 255).round().astype(np.uint32)
    packed = sum(rgba[:, k] << (8 * k) for k in range(rgba.shape[1]))  # one integer per colour
    assert len(np.unique(packed)) > 3
    assert [p.name for p in out.parent.iterdir()] == ["a.png"]  # no temporary file left behind


def test_graph_table_rows_one_per_node(allegro):
    spec, _ = allegro
    rows = graph_table_rows(spec)
    assert [r[0] for r in rows] == [n.id for n in spec.nodes]
    by_joint = {j.joint: j for j in spec.joints}
    for (nid, finger, typ, parent, joints, mask), node in zip(rows, spec.nodes):
        assert len(mask) == 3
        expected = "".join(letter if bit else "·" for letter, bit in zip("FAR", spec.activation_mask[nid]))
        assert mask == expected
        for bit, p, letter in zip(spec.activation_mask[nid], PRIMITIVES, mask):
            assert (letter != "·") == bool(bit) and (not bit or letter == p[0])
        assert (finger, typ) == (node.finger, node.type)
        assert parent == (node.parent if node.parent is not None else "—")
        for jname in node.joints:
            row = by_joint[jname]
            assert f"{jname} {row.primitive.value}{'+' if row.sign > 0 else '-'}" in joints
    wrist = rows[0]
    assert wrist[3] == "—" and wrist[5] == "···"
    assert any(r[4].startswith("joint_0.0 ABD") for r in rows)
