"""Pure-Python fake devices on pseudo-terminals, for tests and ``dgz deploy --fake``."""

from __future__ import annotations

from dgz_cli.hw.fakes.base import FAULTS, PtyFake


def fake_for(cfg, **kw) -> PtyFake:
    """A started-not-yet fake that matches a hand file (protocol, slave id, motor ids)."""
    if cfg.protocol == "revo2_modbus":
        from dgz_cli.hw.fakes.revo2 import Revo2Fake

        kw.setdefault("slave", cfg.slave_id)
        return Revo2Fake(**kw)
    if cfg.protocol == "inspire_modbus":
        from dgz_cli.hw.fakes.inspire import InspireFake

        kw.setdefault("slave", cfg.slave_id)
        return InspireFake(**kw)
    from dgz_cli.hw.fakes.dynamixel import DynamixelFake

    kw.setdefault("ids", [c.id for c in cfg.channels])
    return DynamixelFake(**kw)


__all__ = ["FAULTS", "PtyFake", "fake_for"]
