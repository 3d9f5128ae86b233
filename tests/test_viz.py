"""`dgz show`: the node table and the PNG of the graph over the skeleton."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from conftest import SPECS
from dgz_cli.spec.io import load_spec
from dgz_cli.viz.show import graph_table_rows


def test_table_rows_match_spec():
    spec = load_spec(SPECS / "dgz_tri" / "spec.yaml")
    rows = graph_table_rows(spec)
    assert [r[0] for r in rows] == [n.id for n in spec.nodes]
    for (nid, _, _, _, joints, mask), node in zip(rows, spec.nodes):
        assert mask == "".join(c if b else "·" for c, b in zip("FAR", spec.activation_mask[nid]))
        for j in node.joints:
            assert j in joints
    assert "index_dip mimic(index_pip)" in dict((r[0], r[4]) for r in rows)["middle_distal"]


def test_show_png(tmp_path):
    import matplotlib.image

    png = tmp_path / "tri.png"
    res = subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", "show", "dgz_tri", "--png", str(png)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "thumb_proximal" in res.stdout and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = matplotlib.image.imread(str(png))
    assert img.shape[0] > 400 and img.shape[1] > 800
    assert len(np.unique(img.reshape(-1, img.shape[-1])[::97], axis=0)) > 3  # not blank
    assert not list(tmp_path.glob(".*tmp*"))


def test_show_unknown_hand(tmp_path):
    res = subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", "show", "nohand"], capture_output=True, text=True)
    assert res.returncode == 1 and "unknown hand 'nohand'" in res.stderr and "Traceback" not in res.stderr
