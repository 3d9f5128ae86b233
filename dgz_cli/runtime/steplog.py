"""Step log (JSON Lines) and replay on the simulated hand.

Line 1 ``{"type": "header", ...}`` (hand, spec, joints, rate, device identity), then one
``{"type": "step", ...}`` per control step (phase, action, wrist command raw/filtered, target, measured,
effort, loop time, overrun, bus errors), then ``{"type": "end", ...}`` with the stop reason.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

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
            import os
            import stat

            try:  # a device (/dev/full), FIFO or folder is refused; a symlink is written through
                st = os.stat(self.path)
                if not stat.S_ISREG(st.st_mode):
                    raise DgzError(f"--log {self.path}: it exists and is not a regular file",
                                   "name a new or regular file for the step log")
            except FileNotFoundError:
                pass
            except OSError as exc:
                raise DgzError(f"--log {self.path}: {exc.strerror or exc}", "choose another log path") from None
            try:
                self.path.parent.mkdir(parents=True, exist_ok=True)
                self.fh = self.path.open("w", encoding="utf-8")
            except OSError as exc:
                raise DgzError(f"--log {self.path}: cannot be written ({exc.strerror or exc})",
                               "choose a writable log path") from None
        self.steps = 0

    def _write(self, record: dict, *, quiet: bool = False) -> None:
        if self.fh is not None:
            try:
                self.fh.write(json.dumps(_plain(record), separators=(",", ":")) + "\n")
                self.fh.flush()
            except OSError as exc:  # disk full, ...: stop logging; a header/step failure stops the run safely
                self.close()
                if not quiet:
                    raise DgzError(f"--log {self.path}: cannot be written ({exc.strerror or exc})",
                                   "free disk space or choose another log path") from None

    def header(self, **fields) -> None:
        self._write({"type": "header", "wall_time": time.time(), **fields})

    def step(self, **fields) -> None:
        self.steps += 1
        self._write({"type": "step", **fields})

    def end(self, **fields) -> None:
        self._write({"type": "end", **fields}, quiet=True)  # never fails the exit path

    def close(self) -> None:
        if self.fh is not None:
            fh, self.fh = self.fh, None
            try:
                fh.close()
            except OSError:
                pass


MAX_LOG_BYTES = 256 * 1024 * 1024
MAX_JOINTS = 64
_Finite = Annotated[float, Field(allow_inf_nan=False, ge=-1e3, le=1e3)]  # rad (or m): any joint value
_Name = Annotated[str, Field(min_length=1, max_length=200)]


class _Record(BaseModel):
    """What replay and the callers of :func:`read_log` rely on; other fields pass through untouched."""

    model_config = ConfigDict(extra="allow")


class LogHeader(_Record):
    type: Literal["header"]
    spec: _Name
    joints: list[_Name] = Field(min_length=1, max_length=MAX_JOINTS)
    rate_hz: Annotated[float, Field(allow_inf_nan=False, gt=0, le=10_000)] = 20.0


class LogStep(_Record):
    type: Literal["step"]
    target: list[_Finite] | None = Field(None, max_length=MAX_JOINTS)
    measured: list[_Finite] | None = Field(None, max_length=MAX_JOINTS)


class LogEnd(_Record):
    type: Literal["end"]
    reason: Annotated[str, Field(max_length=10_000)] | None = None


_KINDS = {"header": LogHeader, "step": LogStep, "end": LogEnd}


def _check(model, rec: dict, where: str) -> None:
    try:
        model.model_validate(rec)
    except ValidationError as exc:
        e = exc.errors()[0]
        loc = ".".join(str(p) for p in e["loc"]) or "(record)"
        raise DgzError(f"{where}: field '{loc}': {e['msg']}",
                       "the log is damaged or not a dgz step log: record a new one with `dgz deploy --log`") from None


def read_log(path: Path) -> tuple[dict, list[dict], dict | None]:
    """A step log's header, steps and end record; every record is schema-checked (finite, bounded joint values,
    as many as the header's joints) and any problem is one :class:`DgzError` naming the file, line and field."""
    from dgz_cli.spec.io import read_text_bounded

    path = Path(path)
    text = read_text_bounded(path, MAX_LOG_BYTES, DgzError)
    header, steps, end = None, [], None
    for n, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except (json.JSONDecodeError, RecursionError):
            raise DgzError(f"{path}:{n}: not a JSON line", "the log is truncated or not a dgz step log") from None
        if not isinstance(rec, dict) or rec.get("type") not in _KINDS:
            raise DgzError(f"{path}:{n}: not a step-log record (no 'type' header/step/end)",
                           "the log is damaged or not a dgz step log")
        kind = rec["type"]
        _check(_KINDS[kind], rec, f"{path}:{n}")
        if kind == "header":
            if header is not None:
                raise DgzError(f"{path}:{n}: a second header line", "one log holds one run")
            header = rec
        elif header is None:
            raise DgzError(f"{path}:{n}: a {kind} record before the header line", "the log is not a dgz step log")
        elif kind == "step":
            for key in ("target", "measured"):
                if rec.get(key) is not None and len(rec[key]) != len(header["joints"]):
                    raise DgzError(f"{path}:{n}: field '{key}': {len(rec[key])} values for the header's "
                                   f"{len(header['joints'])} joints", "the log is damaged or not a dgz step log")
            steps.append(rec)
        else:
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
