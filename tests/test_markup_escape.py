"""Names that come from input files print literally in `dgz bench` and `dgz deploy` (issue 10 item 10)."""

from __future__ import annotations

import pytest
from rich.console import Console
from typer.testing import CliRunner

from dgz_cli.cli import app as app_mod
from dgz_cli.cli import deploy_cmd
from dgz_cli.hw.arm import ArmInterface
from dgz_cli.spec.contract import ControlContract, EpisodeProtocol

LINK = "[link=file:///etc/passwd]f0[/link]"
BOLD = "[bold red]loud[/]"


def console() -> Console:
    return Console(width=300, force_terminal=False, record=True, emoji=False)


def test_deploy_prints_the_arm_name_literally(monkeypatch):
    class Odd(ArmInterface):
        name = LINK

    monkeypatch.setattr(deploy_cmd, "_make_arm", lambda *a, **k: Odd())
    out = console()
    contract = ControlContract(episode=EpisodeProtocol(control_hz=100.0, grasp_steps=3, lift_steps=0, hold_s=0.0))
    assert deploy_cmd.run("revo2", None, "close", None, True, True, True, None, "hold", None, out,
                          contract=contract) == 0
    assert f"arm {LINK}:" in out.export_text()


def test_deploy_replay_prints_the_logged_spec_and_reason_literally(monkeypatch, tmp_path):
    from dgz_cli.runtime import steplog

    summary = {"steps": 3, "spec": BOLD, "max_tracking_error": 0.1, "final_tracking_error": 0.01,
               "logged_reason": LINK}
    monkeypatch.setattr(steplog, "replay", lambda path, asset_root=None: summary)
    out = console()
    assert deploy_cmd.run(None, None, "close", None, False, False, True, None, "hold", tmp_path / "x.jsonl", out) == 0
    text = out.export_text()
    assert BOLD in text and f"(logged stop: {LINK})" in text


def test_bench_onboard_table_prints_hand_names_literally(monkeypatch):
    from dgz_cli.bench import onboard_bench

    row = {"parse_s": 0.1, "compile_s": 0.2, "excite_s": 0.3, "onboard_s": 0.6}
    monkeypatch.setattr(onboard_bench, "run", lambda *a, **k: {"hands": {LINK: row, ":x:": row}})
    r = CliRunner().invoke(app_mod.app, ["bench", "onboard"], env={"COLUMNS": "300"})
    assert r.exit_code == 0, r.output
    assert LINK in r.output and ":x:" in r.output and "❌" not in r.output


def test_bench_policy_prints_the_preset_literally(monkeypatch):
    from dgz_cli.bench import policy_bench

    result = {"batch1_forward_ms": 1.0, "forward_graphs_per_s_b1024": 2, "ppo_update_samples_per_s": 3}
    monkeypatch.setattr(policy_bench, "run", lambda *a, **k: result)
    r = CliRunner().invoke(app_mod.app, ["bench", "policy", "--preset", BOLD], env={"COLUMNS": "300"})
    assert r.exit_code == 0, r.output
    assert f"{BOLD}: batch-1 forward" in r.output


@pytest.mark.parametrize("name", [LINK, BOLD])
def test_deploy_escapes_are_needed(name):
    """The check above can fail: unescaped, rich swallows the markup."""
    out = console()
    out.print(f"arm {name}:")
    assert name not in out.export_text()
