"""Hand name → (hand file, HandSpec, driver). The only place that knows which class speaks which protocol."""

from __future__ import annotations

from dgz_cli.hw.config import HandConfig, load_hand_config
from dgz_cli.hw.driver import HandDriver
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.io import load_spec
from dgz_cli.spec.models import HandSpec

SIM_HAND = "dgz_tri"  # `--hand sim`: the built-in hand that needs no vendor assets


def load_hand(name_or_path: str) -> tuple[HandConfig, HandSpec]:
    cfg = load_hand_config(name_or_path)
    return cfg, load_spec(resolve_spec(cfg.spec))


def make_driver(cfg: HandConfig, spec: HandSpec, port: str) -> HandDriver:
    if cfg.protocol == "revo2_modbus":
        from dgz_cli.hw.revo2 import Revo2Driver

        return Revo2Driver(cfg, spec, port)
    if cfg.protocol == "inspire_modbus":
        from dgz_cli.hw.inspire import InspireDriver

        return InspireDriver(cfg, spec, port)
    from dgz_cli.hw.leap import LeapDriver

    return LeapDriver(cfg, spec, port)


def make_sim_driver(spec_ref: str = SIM_HAND, asset_root: str | None = None, **kw) -> HandDriver:
    """The MuJoCo-simulated hand for a shipped spec name or spec path."""
    from dgz_cli.hw.sim_hand import SimHand

    return SimHand(load_spec(resolve_spec(spec_ref)), asset_root=asset_root, **kw)
