"""`dgz train` saves and exits 130 on SIGTERM and SIGHUP (a closed terminal), like Ctrl-C (issue 10 item 3)."""

from __future__ import annotations

import os
import signal
import time
from types import SimpleNamespace

import pytest
from rich.console import Console

from dgz_cli.cli import train_cmd


class StubTrainer:
    """Stands in for rl.runner.Trainer: its train() receives a signal mid-run, saves on KeyboardInterrupt and
    re-raises, as the real one does."""

    def __init__(self, sig) -> None:
        self.sig, self.iteration, self.history, self.saved = sig, 3, [], 0
        self.env = SimpleNamespace(B=1, close=lambda: None)

    def train(self) -> None:
        try:
            os.kill(os.getpid(), self.sig)
            end = time.monotonic() + 5
            while time.monotonic() < end:  # the handler runs between bytecodes
                time.sleep(0.01)
            raise AssertionError("the signal did not interrupt training")
        except KeyboardInterrupt:
            self.saved += 1
            raise


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_train_saves_and_exits_130_on_sigterm_and_sighup(tmp_path, monkeypatch, sig):
    trainer = StubTrainer(sig)
    monkeypatch.setattr(train_cmd, "build", lambda *a, **k: trainer)
    before = {s: signal.getsignal(s) for s in (signal.SIGTERM, signal.SIGHUP)}
    out = Console(width=200, record=True)
    assert train_cmd.run({}, None, tmp_path / "run", False, None, out) == 130
    assert trainer.saved == 1 and "interrupted: saved iteration 3" in out.export_text()
    assert {s: signal.getsignal(s) for s in before} == before  # handlers restored after the run
