"""Issue 13, the last items: hand variants for training diversity (`dgz hands generate --variants-of`), training on
a folder of generated hands (`dgz train --hands dgz_tri,generated:DIR`), and `dgz bench onboard --generated N`.
Everything runs on the built-in dgz_tri hand (no vendor assets)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from dgz_cli.onboard.agreement import check_dir, summary
from dgz_cli.onboard.generate import load_labels, write_hands
from dgz_cli.onboard.urdf import load_kinematics
from dgz_cli.onboard.variants import SCALE_RANGE, write_variants
from dgz_cli.spec.catalog import resolve_spec, resolve_urdf
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.io import load_spec


@pytest.fixture(scope="module")
def base():
    spec = load_spec(resolve_spec("dgz_tri"))
    return spec, resolve_urdf(spec.provenance.urdf)


def test_variants_are_deterministic_scaled_and_labelled_by_construction(base, tmp_path):
    spec, urdf = base
    a = write_variants(spec, urdf, tmp_path / "a", 3, 8)
    b = write_variants(spec, urdf, tmp_path / "b", 3, 8)
    assert [p.read_bytes() for pair in a for p in pair] == [p.read_bytes() for pair in b for p in pair]
    base_kin = load_kinematics(urdf)
    finger_of = {j: n.finger for n in spec.nodes for j in n.joints}
    removed = 0
    for u, lab in a:
        labels, kin = load_labels(lab), load_kinematics(u)
        assert labels.kind == "variant"
        assert {x.joint for x in labels.joints} == {j.name for j in kin.actuated}, labels.name
        removed += len(base_kin.actuated) - len(kin.actuated)
        for x in labels.joints:  # primitive and sign are the reviewed base spec's
            row = next(r for r in spec.joints if r.joint == x.joint)
            assert (x.primitive, x.sign) == (row.primitive.value, row.sign)
        ratios: dict[str, set] = {}
        for name, j in kin.joints.items():  # every finger's links scaled by one factor in range
            b0 = base_kin.joints[name].origin[:3, 3]
            f = finger_of.get(name)
            parent_joint = base_kin.parent_joint(j.parent)
            if f is not None and parent_joint is not None and finger_of.get(parent_joint.name) == f and np.linalg.norm(b0) > 1e-6:
                ratios.setdefault(f, set()).add(round(float(np.linalg.norm(j.origin[:3, 3]) / np.linalg.norm(b0)), 3))
        assert ratios and all(len(r) == 1 and SCALE_RANGE[0] <= next(iter(r)) <= SCALE_RANGE[1] for r in ratios.values())
    assert removed > 0  # some variant lost a fingertip joint
    result = summary(check_dir(tmp_path / "a"))  # onboarding agrees with the construction on these
    assert result["hands"] == 8 and result["wrong"] == 0 and result["false_refusal"] == 0, result["failures"]


def test_train_on_a_generated_folder_records_its_hands(base, tmp_path):
    from dgz_cli.cli.train_cmd import build
    from dgz_cli.rl.checkpoint import read_meta
    from dgz_cli.rl.config import TrainConfig

    spec, urdf = base
    folder = tmp_path / "gen"
    write_variants(spec, urdf, folder, 1, 2)
    cfg = TrainConfig(hands=("dgz_tri", f"generated:{folder}"), objects="sphere", iterations=1, steps_per_env=4,
                      repeat=1, checkpoint_every=1, seed=0)
    trainer = build(cfg, tmp_path / "run", None)
    try:
        trainer.train()
    finally:
        trainer.env.close()
    specs = sorted(folder.glob("*.yaml"))
    assert [p.stem for p in specs] == ["dgz_tri_v1_0000", "dgz_tri_v1_0001"]
    hands = read_meta(tmp_path / "run").training_hands
    assert set(hands) == {"dgz_tri", "dgz_tri_v1_0000", "dgz_tri_v1_0001"}
    for p in specs:
        assert hands[p.stem] == hashlib.sha256(p.read_bytes()).hexdigest()
        assert load_spec(p).provenance.urdf == str(p.with_suffix(".urdf").resolve())  # absolute: builds anywhere
    # a second resolution reuses the current specs instead of onboarding again
    from dgz_cli.cli.hand_refs import hand_specs

    before = [p.stat().st_mtime_ns for p in specs]
    assert list(hand_specs((f"generated:{folder}",), None).values()) == specs
    assert [p.stat().st_mtime_ns for p in specs] == before


def test_distill_on_a_generated_folder_records_its_hands(base, tmp_path):
    from dgz_cli.cli.distill_cmd import build
    from dgz_cli.rl.distill_config import DistillConfig

    spec, urdf = base
    folder = tmp_path / "gen"
    write_variants(spec, urdf, folder, 3, 1)
    cfg = DistillConfig(teacher="dgz-cpu-warmstart", hands=("dgz_tri", f"generated:{folder}"), objects="sphere",
                        iterations=1, steps_per_env=4, epochs=1, threads=1)
    dist = build(cfg, tmp_path / "student", None)
    try:
        assert dist.env.B == 2
        assert dist.training_hands == {"dgz_tri": dist.training_hands["dgz_tri"],
                                       "dgz_tri_v3_0000": hashlib.sha256((folder / "dgz_tri_v3_0000.yaml").read_bytes()).hexdigest()}
    finally:
        dist.env.close()


@pytest.mark.parametrize("make", ["missing", "empty", "file"])
def test_a_bad_generated_folder_is_one_clear_line(tmp_path, make):
    from dgz_cli.cli.hand_refs import hand_specs

    folder = tmp_path / "hands"
    if make == "empty":
        folder.mkdir()
    elif make == "file":
        folder.write_text("x")
    with pytest.raises(DgzError) as exc:
        hand_specs(("dgz_tri", f"generated:{folder}"), None)
    assert str(folder) in exc.value.message and "\n" not in exc.value.message
    assert "dgz hands generate" in exc.value.hint


def test_bench_onboard_generated_reports_the_rates(capsys):
    from dgz_cli.cli.app import app

    app(["bench", "onboard", "--generated", "12", "--seed", "7", "--json"], standalone_mode=False)
    result = json.loads(capsys.readouterr().out)
    assert result["hands"] == 12 and result["seed"] == 7
    assert sum(result[k] for k in ("agree", "refused", "wrong", "false_refusal")) == 12
    assert result["agreement"] == round(result["agree"] / 12, 4) and result["refusal_rate"] == round(result["refused"] / 12, 4)
    assert result["wrong"] == 0 and result["false_refusal"] == 0
    assert len(result["load_average"]) == 3


def test_hands_check_still_reads_a_generated_folder(tmp_path, capsys):
    from dgz_cli.cli.app import app

    write_hands(tmp_path, 5, 3)
    try:
        app(["hands", "check", str(tmp_path), "--json"], standalone_mode=False)
    except SystemExit as exc:  # typer.Exit inside standalone_mode=False
        assert exc.code == 0
    out = capsys.readouterr().out
    assert json.loads(out[out.index("{"):])["hands"] == 3


def test_bench_onboard_process_times_a_whole_dgz_onboard(capsys):
    """`dgz bench onboard --process`: a fresh `dgz onboard` process per hand, timed from spawn to exit."""
    from dgz_cli.cli.app import app

    app(["bench", "onboard", "--process", "--hands", "dgz_tri", "--repeat", "1", "--json"], standalone_mode=False)
    result = json.loads(capsys.readouterr().out)
    row = result["hands"]["dgz_tri"]
    assert set(result["hands"]) == {"dgz_tri"} and 0 < row["import_s"] and 0 < row["cpu_s"] and 0 < row["wall_s"]
    assert row["wall_s"] > result["python_startup_s"]  # the onboarding process does more than start Python
    assert result["target_met"] == (result["wall_max_s"] <= 0.5) and len(result["load_average_before"]) == 3


@pytest.mark.skipif(__import__("conftest").asset_root() is None,
                    reason="DGZ_ASSET_ROOT not set: vendor hand assets unavailable (CI sets it)")
@pytest.mark.parametrize("hand,index", [("leap", 4), ("leap", 9), ("leap", 16), ("allegro", 2), ("schunk_svh", 0)])
def test_variants_with_a_long_thumb_keep_the_thumb_rot_sign(tmp_path, hand, index):
    """Seed 0 variants whose thumb grew long relative to the index finger: the old rule (gap change relative to the
    gap) flipped their thumb ROT sign or left it undecided; the gap change per unit of tip travel does not."""
    from conftest import asset_root
    from dgz_cli.onboard.agreement import check_one
    from dgz_cli.onboard.variants import _Base, make_variant

    spec = load_spec(resolve_spec(hand))
    base = _Base(spec, resolve_urdf(spec.provenance.urdf, str(asset_root())), dict(spec.provenance.xacro_args))
    name = f"{hand}_v0_{index:04d}"
    text, labels = make_variant(base, 0, index, name)
    (tmp_path / f"{name}.urdf").write_text(text)
    rot = [x for x in labels.joints if x.primitive == "ROT"]
    assert rot, "the variant keeps its thumb ROT joint"
    result = check_one(tmp_path / f"{name}.urdf", labels, truth_lint=False)
    assert result.outcome == "agree", result.mismatches or result.error


def test_eval_takes_a_generated_folder_like_train(base, tmp_path):
    """`dgz eval --hand generated:DIR` evaluates every hand in DIR (onboarded there), as `dgz train --hands` does."""
    import subprocess
    import sys

    spec, urdf = base
    folder = tmp_path / "gen"
    write_variants(spec, urdf, folder, 5, 2)
    out = tmp_path / "r.json"
    res = subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", "eval", "--policy", "scripted", "--hand",
                          f"dgz_tri,generated:{folder}", "--objects", "sphere", "--trials", "1", "--json", str(out)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert set(json.loads(out.read_text())["hands"]) == {"dgz_tri", "dgz_tri_v5_0000", "dgz_tri_v5_0001"}
    assert sorted(p.stem for p in folder.glob("*.yaml")) == ["dgz_tri_v5_0000", "dgz_tri_v5_0001"]


def test_eval_names_its_own_option_for_a_bad_folder(tmp_path):
    import subprocess
    import sys

    res = subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", "eval", "--hand", f"generated:{tmp_path / 'no'}",
                          "--objects", "sphere", "--trials", "1"], capture_output=True, text=True)
    assert res.returncode != 0 and "Traceback" not in res.stderr
    line = (res.stdout + res.stderr).strip().splitlines()[0]
    assert line.startswith(f"error: --hand generated:{tmp_path / 'no'}:") and "is not a folder" in line
