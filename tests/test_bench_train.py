"""`dgz bench train`: the JSON it prints describes the run it made (counts, split, profile)."""

from __future__ import annotations

import json

import pytest

from typer.testing import CliRunner

from dgz_cli.cli.app import app


def test_bench_train_reports_throughput_split_and_profile():
    res = CliRunner().invoke(app, ["bench", "train", "--hands", "dgz_tri", "--objects", "sphere,box", "--repeat", "1",
                                   "--steps", "4", "--iterations", "1", "--json"])
    assert res.exit_code == 0, res.output
    r = json.loads(res.stdout[res.stdout.index("{"):])
    assert r["envs"] == 2 and r["transitions"] == 2 * 4 * 1
    assert r["transitions_per_s"] == pytest.approx(r["transitions"] / r["wall_s"], rel=0.01)  # wall_s is rounded to 0.1 ms
    assert r["split_s"]["physics_s"] > 0 and r["split_s"]["ppo_update_s"] > 0 and min(r["split_s"].values()) >= 0
    assert 0.5 < sum(r["split_fraction"].values()) <= 1.01  # the four parts are most of the wall clock, never more
    mj = r["mujoco"]
    assert mj["physics_steps"] == 2 * 5 * 20  # 2 slots × 5 control steps × 20 substeps (400 Hz / 20 Hz)
    assert 0 < mj["share_of_mj_step"]["position"] <= 1 and mj["mean_solver_iterations"] >= 0
    assert r["peak_rss_mb"] > 50
