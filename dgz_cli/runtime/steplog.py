"""Step log (JSON Lines) and replay on the simulated hand.

Line 1 ``{"type": "header", ...}`` (hand, spec, joints, rate, device identity), then one
``{"type": "step", ...}`` per control step (phase, action, wrist command raw/filtered, target, measured,
effort, loop time, overrun, bus errors), then ``{"type": "end", ...}`` with the stop reason.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from dgz_cli.spec.errors import DgzError


def _plain(value):
    if isinstance(value, np.ndarray):
        return [round(float(v), 6) for v in value.reshape(-1)]
    if isinstance(value, (np.floating, float)):
        return round(float(value), 6)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


class StepLogger:
    """Writes one JSON object per line and flushes it, so a crash keeps every finished step."""

    def __init__(self, path: Path | None) -> None:
        self.path = Path(path) if path else None
        self.fh = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.fh = self.path.open("w", encoding="utf-8")
        self.steps = 0

    def _write(self, record: dict) -> None:
        if self.fh is not None:
            self.fh.write(json.dumps(_plain(record), separators=(",", ":")) + "\n")
            self.fh.flush()

    def header(self, **fields) -> None:
        self._write({"type": "header", "wall_time": time.time(), **fields})

    def step(self, **fields) -> None:
        self.steps += 1
        self._write({"type": "step", **fields})

    def end(self, **fields) -> None:
        self._write({"type": "end", **fields})

    def close(self) -> None:
        if self.fh is not None:
            self.fh.close()
            self.fh = None


def read_log(path: Path) -> tuple[dict, list[dict], dict | None]:
    path = Path(path)
    if not path.is_file():
        raise DgzError(f"{path}: no such log file", "pass a file written by `dgz deploy --log`")
    header, steps, end = None, [], None
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except json.JSONDecodeError:
            raise DgzError(f"{path}:{n}: not a JSON line", "the log is truncated or not a dgz step log") from None
        kind = rec.get("type")
        if kind == "header":
            header = rec
        elif kind == "step":
            steps.append(rec)
        elif kind == "end":
            end = rec
    if header is None:
        raise DgzError(f"{path}: no header line", "the log is not a dgz step log")
    return header, steps, end


def replay(path: Path, driver=None, asset_root: str | None = None) -> dict:
    """Play a log's targets back on the simulated hand; report how well the sim tracked them."""
    header, steps, end = read_log(path)
    if driver is None:
        from dgz_cli.hw.factory import make_sim_driver

        driver = make_sim_driver(header["spec"], asset_root=asset_root, control_dt=1.0 / header.get("rate_hz", 20.0))
    errors, dev = [], []
    with driver:
        if list(driver.joint_names) != list(header["joints"]):
            raise DgzError(f"{path}: logged joints do not match spec '{header['spec']}'",
                           "replay with the spec the log was recorded with")
        driver.enable()
        for rec in steps:
            target = rec.get("target")
            if target is None:
                continue
            driver.write_targets(np.array(target))
            q = driver.read_state().q
            errors.append(float(np.max(np.abs(q - np.array(target)))))
            if rec.get("measured") is not None:
                dev.append(float(np.max(np.abs(q - np.array(rec["measured"])))))
    return {"log": str(path), "spec": header["spec"], "steps": len(errors),
            "max_tracking_error": max(errors, default=0.0),
            "final_tracking_error": errors[-1] if errors else 0.0,
            "max_sim_vs_logged": max(dev, default=0.0),
            "logged_reason": (end or {}).get("reason")}
