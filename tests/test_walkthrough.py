"""The README's "from zero to a zero-shot grasp on your hand" walkthrough, run line by line as written, in a fresh
HOME (so `~/.cache/dgz/assets` is the default asset root) without DGZ_ASSET_ROOT.

Offline, the upstream archives come from a loopback mirror (``DGZ_ASSET_MIRROR``) that serves fixture archives
rebuilt from the reference asset root; the fetch line gets ``--registry`` with one change from the shipped
registry: the YCB visuals' sha256 are those of the reference root's decimated copies (upstream's 16k visuals are
not at hand offline). Every other file is checked against the shipped registry's sha256.
"""

from __future__ import annotations

import json
import os
import re
import subprocess

from conftest import REPO, asset_root, needs_assets
from test_assets_fetch import make_tar, server, sha, upstream_members  # noqa: F401 (server is a fixture)

from dgz_cli.assets.registry import Registry, shipped_registry


def walkthrough_lines() -> list[str]:
    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text.split("## From zero to a zero-shot grasp on your hand", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    return [ln.split("  #")[0].strip() for ln in block.splitlines() if ln.strip()]


def offline_registry(tmp_path) -> tuple[Registry, str]:
    reg = shipped_registry()
    ycb = reg.units["objects/ycb45"]
    files = {p: (f.model_copy(update=dict(sha256=sha((asset_root() / "objects/ycb45" / p).read_bytes())))
                 if p.endswith("visual.obj") else f) for p, f in ycb.files.items()}
    units = dict(reg.units, **{"objects/ycb45": ycb.model_copy(update=dict(files=files))})
    offline = reg.model_copy(update=dict(units=units))
    path = tmp_path / "registry.json"
    path.write_text(json.dumps(offline.model_dump(mode="json")))
    return offline, str(path)


@needs_assets()
def test_readme_walkthrough_runs_as_written(server, tmp_path):  # noqa: F811
    httpd, url, handler = server
    lines = walkthrough_lines()
    assert [ln.split()[1] for ln in lines] == ["assets", "onboard", "eval", "deploy"]
    reg, reg_path = offline_registry(tmp_path)
    handler.files[reg.sources["dex-urdf"].archive] = make_tar(upstream_members(reg, "hands/leap", asset_root()))
    handler.files[reg.sources["YCB_Dataset"].archive] = make_tar(upstream_members(reg, "objects/ycb45", asset_root()))
    home = tmp_path / "home"
    home.mkdir()
    (tmp_path / ".venv").symlink_to(REPO / ".venv")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("DGZ_", "XDG_")) and k not in ("DISPLAY", "MUJOCO_GL")}
    env.update(HOME=str(home), DGZ_ASSET_MIRROR=url, COLUMNS="200")
    outputs = []
    for line in lines:
        cmd = line + (f" --registry {reg_path} --quiet" if line.split()[1] == "assets" else "")
        proc = subprocess.run(["bash", "-c", cmd], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, f"{line}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
        assert "Traceback" not in proc.stderr
        outputs.append(proc.stdout)
    cache = home / ".cache" / "dgz" / "assets"
    assert json.loads((cache / ".dgz-assets.json").read_text())["units"].keys() == {"hands/leap", "objects/ycb45"}
    assert len(list((cache / "objects/ycb45").glob("*/model.xml"))) == 45
    assert (tmp_path / "my_hand.yaml").is_file()
    assert "my_hand" in outputs[2]  # the eval table names the onboarded hand
    videos = tmp_path / "videos"
    if "skipping --video" not in outputs[2] or os.environ.get("CI"):  # CI installs EGL: there it must render
        assert (videos / "my_hand_025_mug_ep0.mp4").is_file() and (videos / "contact_sheet.png").is_file()
    assert "done: 190 steps" in outputs[3]
