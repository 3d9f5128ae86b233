"""`dgz train` and `dgz distill` as real processes: SIGTERM mid-run saves the current iteration atomically and
exits 130, and `--resume` continues from exactly that iteration to the end (issue 10 item 3, issue 12). Runs on
the built-in dgz_tri × sphere, so no vendor asset is needed."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

RUNS = {
    "train": ["train", "--hands", "dgz_tri", "--objects", "sphere", "--repeat", "1", "--steps", "20",
              "--checkpoint-every", "1"],
    "distill": ["distill", "--teacher", "dgz-cpu-warmstart", "--hands", "dgz_tri", "--objects", "sphere",
                "--steps", "20", "--epochs", "1", "--checkpoint-every", "1"],
}


def _history(out: Path) -> list[int]:
    path = out / "history.jsonl"
    if not path.is_file():
        return []
    return [json.loads(line)["iteration"] for line in path.read_text().splitlines() if line.strip()]


def _saved_iteration(out: Path) -> int:
    return int(yaml.safe_load((out / "checkpoint.yaml").read_text())["iteration"])


def _env() -> dict:
    return dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", COLUMNS="200")


@pytest.mark.parametrize("command", sorted(RUNS))
def test_sigterm_saves_and_resume_continues(tmp_path, command):
    out = tmp_path / "run"
    args = [sys.executable, "-m", "dgz_cli.cli.app", *RUNS[command], "--out", str(out)]
    proc = subprocess.Popen([*args, "--iterations", "400"], cwd=tmp_path, env=_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 240
        while len(_history(out)) < 2 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()
        assert len(_history(out)) >= 2, "no two iterations within 240 s"
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, (stdout, stderr)
    assert "Traceback" not in stderr, stderr
    saved = _saved_iteration(out)
    assert f"interrupted: saved iteration {saved}" in " ".join(stdout.split())
    assert (out / f"model-{saved:07d}.safetensors").is_file()
    assert _history(out) == list(range(1, saved + 1))  # the log holds exactly the saved iterations
    assert not list(out.glob("*.tmp*")), "a half-written file was left behind"

    res = subprocess.run([*args, "--resume", "--iterations", str(saved + 1)], cwd=tmp_path, env=_env(),
                         capture_output=True, text=True, timeout=240)
    assert res.returncode == 0, (res.stdout, res.stderr)
    assert f"from iteration {saved}" in " ".join(res.stdout.split())
    assert _saved_iteration(out) == saved + 1
    assert _history(out) == list(range(1, saved + 2))
