"""A wheel built with `python -m build` ships the hand registry and the policies, and works outside the checkout.

The wheel is built from a copy of the sources (the shared checkout gets no build/ folder), installed with
``pip install --no-deps`` into a fresh venv that sees this environment's packages (torch, mujoco: nothing is
downloaded) but not the editable install, and run from a folder outside the checkout: `dgz show leap` and a
one-trial `dgz eval` of a shipped policy on the built-in hand and a built-in object.
"""

from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from conftest import REPO

SOURCES = ("dgz_cli", "hand_specs", "policies", "pyproject.toml", "setup.py", "MANIFEST.in", "README.md")


def _run(cmd: list[str], cwd: Path, env: dict | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, env=env, timeout=timeout)
    assert proc.returncode == 0, f"{' '.join(map(str, cmd))}\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    return proc


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    pytest.importorskip("build", reason="`build` (in the test extra) builds the wheel")
    src = tmp_path_factory.mktemp("src")
    for name in SOURCES:
        p = REPO / name
        if p.is_dir():
            shutil.copytree(p, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "shipped"))
        else:
            shutil.copy2(p, src / name)
    dist = tmp_path_factory.mktemp("dist")
    # --no-isolation: setuptools comes from this environment (no download)
    _run([sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", str(dist), str(src)], cwd=src)
    (whl,) = dist.glob("dgz-*.whl")
    return whl


def test_wheel_ships_hand_specs_policies_and_the_asset_registry(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    for spec in REPO.glob("hand_specs/*/spec.yaml"):
        assert f"dgz_cli/shipped/hand_specs/{spec.parent.name}/spec.yaml" in names
    for f in REPO.glob("policies/*/checkpoint.yaml"):
        folder = f.parent.name
        assert f"dgz_cli/shipped/policies/{folder}/checkpoint.yaml" in names
        weights = [n for n in names if n.startswith(f"dgz_cli/shipped/policies/{folder}/") and n.endswith(".safetensors")]
        assert weights, folder
    assert "dgz_cli/assets/registry.json" in names and "dgz_cli/data/hands/dgz_tri.urdf" in names
    assert not any(n.startswith(("hand_specs/", "policies/", "tests/")) for n in names)  # nothing top-level


def test_installed_wheel_shows_leap_and_evaluates_a_shipped_policy(wheel, tmp_path):
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=tmp_path)
    purelib = next(venv.glob("lib/python*/site-packages"))
    # this environment's packages (torch, mujoco, ...) without their .pth files: the editable dgz stays invisible
    (purelib / "dgz_env.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    py = venv / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", "--no-index", str(wheel)],
         cwd=tmp_path)
    env = {k: v for k, v in os.environ.items() if not k.startswith("DGZ_") and k not in ("PYTHONPATH",)}
    env.update(COLUMNS="200", XDG_CACHE_HOME=str(tmp_path / "cache"))
    where = _run([str(py), "-c", "import dgz_cli.spec.catalog as c; print(c.__file__); print(c.specs_dir()); "
                  "print(c.policies_dir())"], cwd=tmp_path, env=env).stdout.split()
    assert all(Path(w).is_relative_to(venv) for w in where), where  # the wheel's files, not the checkout's
    dgz = str(venv / "bin" / "dgz")
    show = _run([dgz, "show", "leap"], cwd=tmp_path, env=env)
    assert "leap" in show.stdout and "thumb" in show.stdout
    out = tmp_path / "eval.json"
    _run([dgz, "eval", "--policy", "dgz-cpu-warmstart", "--hand", "dgz_tri", "--objects", "sphere", "--trials", "1",
          "--json", str(out)], cwd=tmp_path, env=env)
    report = json.loads(out.read_text())
    assert report["policy"] == "dgz-cpu-warmstart" and report["hands"]["dgz_tri"]["episodes"] == 1
