"""`dgz train` saves and exits 130 on Ctrl-C, SIGTERM and SIGHUP (a closed terminal) (issue 10 item 3). The
first signal only requests a stop, which the loop honours at its next step (a handler that raised would break
the physics pool's wait); a second one interrupts at once."""

from __future__ import annotations

import os
import signal
import time
from types import SimpleNamespace

import pytest
from rich.console import Console

from dgz_cli.cli import train_cmd
from dgz_cli.rl.stop import StopRequest


class StubTrainer:
    """Stands in for rl.runner.Trainer: its train() receives ``signals`` mid-run, keeps working for a while
    (recording whether the handler raised), checks its stop request between "steps" as the real loops do,
    saves on KeyboardInterrupt and re-raises."""

    def __init__(self, signals) -> None:
        self.signals, self.iteration, self.history, self.saved = signals, 3, [], 0
        self.steps_after_signal = 0
        self.stop = StopRequest()
        self.env = SimpleNamespace(B=1, close=lambda: None)

    def train(self) -> None:
        try:
            for sig in self.signals:
                os.kill(os.getpid(), sig)
            end = time.monotonic() + 0.3
            while time.monotonic() < end:  # a step in flight: the handler runs between bytecodes
                time.sleep(0.01)
                self.steps_after_signal += 1
            self.stop.check()
            raise AssertionError("the stop request was not set")
        except KeyboardInterrupt:
            self.saved += 1
            raise


def _run(trainer, tmp_path, monkeypatch):
    monkeypatch.setattr(train_cmd, "build", lambda *a, **k: trainer)
    out = Console(width=200, record=True)
    return train_cmd.run({}, None, tmp_path / "run", False, None, out), out.export_text()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["SIGINT", "SIGTERM", "SIGHUP"])
def test_train_saves_and_exits_130_at_the_next_step(tmp_path, monkeypatch, sig):
    trainer = StubTrainer([sig])
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    code, text = _run(trainer, tmp_path, monkeypatch)
    assert code == 130 and trainer.saved == 1 and "interrupted: saved iteration 3" in text
    assert trainer.steps_after_signal > 0  # the handler did not raise mid-step: the step went on
    assert {s: signal.getsignal(s) for s in before} == before  # handlers restored after the run


def test_a_second_signal_interrupts_at_once(tmp_path, monkeypatch):
    trainer = StubTrainer([signal.SIGTERM, signal.SIGTERM])
    code, text = _run(trainer, tmp_path, monkeypatch)
    assert code == 130 and trainer.saved == 1
    assert trainer.steps_after_signal == 0  # raised by the handler, before the step went on
