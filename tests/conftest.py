"""Shared fixtures. Vendor assets come from DGZ_ASSET_ROOT; without it those tests skip with a reason."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SPECS = REPO / "hand_specs"
BUILTIN = REPO / "dgz_cli" / "data" / "hands"


def asset_root() -> Path | None:
    value = os.environ.get("DGZ_ASSET_ROOT")
    return Path(value) if value else None


def needs_assets():
    return pytest.mark.skipif(asset_root() is None,
                              reason="DGZ_ASSET_ROOT not set: vendor hand assets unavailable (CI sets it)")


def shipped_specs() -> list[Path]:
    """``hand_specs/<hand>/spec.yaml`` of every shipped hand, by hand name."""
    return sorted(SPECS.glob("*/spec.yaml"))


@pytest.fixture(scope="module")
def one_torch_thread():
    """Tiny graphs: one intra-op thread avoids OpenMP spin-waits when the CPU is shared."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)
