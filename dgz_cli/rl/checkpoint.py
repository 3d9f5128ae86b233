"""Checkpoints: weights as safetensors (no pickle, so loading never runs code) + a YAML of the run.

A checkpoint directory holds ``model.safetensors`` and ``checkpoint.yaml`` (full config, iteration,
training hands with their spec hashes, git revision, metrics). Both are written atomically.
"""

from __future__ import annotations

import hashlib
import subprocess
from pathlib import Path

import yaml

from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import atomic_write_bytes


def git_revision(repo: Path | None = None) -> str | None:
    """HEAD of the dgz checkout, with ``-dirty`` when tracked files have uncommitted changes; None outside git."""
    cwd = repo or Path(__file__).resolve().parents[2]
    try:
        out = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True, timeout=5)
        if out.returncode != 0 or not out.stdout.strip():
            return None
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=cwd,
                               capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() + ("-dirty" if dirty.returncode == 0 and dirty.stdout.strip() else "")


POLICIES_DIR = Path(__file__).resolve().parents[2] / "policies"


def resolve_checkpoint(ref: str) -> Path | None:
    """A checkpoint folder path, or the name of a folder under ``policies/``; None when neither exists."""
    path = Path(ref)
    if path.is_dir():
        return path
    if "/" not in ref and (POLICIES_DIR / ref).is_dir():
        return POLICIES_DIR / ref
    return None


def spec_hash(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def save(directory: Path, tensors: dict, meta: dict) -> None:
    """Write ``tensors`` (name → torch.Tensor) and ``meta`` (plain YAML-able dict) into ``directory``."""
    from safetensors.torch import save

    directory = Path(directory)
    atomic_write_bytes(directory / "model.safetensors", save({k: v.detach().contiguous().cpu() for k, v in tensors.items()}))
    atomic_write_bytes(directory / "checkpoint.yaml", yaml.safe_dump(meta, sort_keys=False).encode())


def load(directory: Path) -> tuple[dict, dict]:
    """(tensors, meta). Never unpickles: safetensors + yaml.safe_load."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    directory = Path(directory)
    weights, meta_file = directory / "model.safetensors", directory / "checkpoint.yaml"
    if not weights.is_file() or not meta_file.is_file():
        raise DgzError(f"{directory}: not a dgz checkpoint (needs model.safetensors and checkpoint.yaml)",
                       "point --policy at a folder written by `dgz train` (e.g. runs/NAME or policies/NAME)")
    try:
        tensors = load_file(str(weights))
    except (SafetensorError, OSError, ValueError) as exc:
        raise DgzError(f"{weights}: unreadable weights ({exc})", "the file is damaged; use an earlier checkpoint") from None
    try:
        meta = yaml.safe_load(meta_file.read_text())
    except yaml.YAMLError as exc:
        raise DgzError(f"{meta_file}: malformed YAML ({exc})", "restore the file from the run directory") from None
    if not isinstance(meta, dict) or "policy" not in meta:
        raise DgzError(f"{meta_file}: missing 'policy' section", "is this a dgz checkpoint?")
    return tensors, meta
