"""Issue 15's `dgz eval` protocol pieces: the URDF-prior sensitivity transform (``spec.transform.scale_lengths``),
the closing onset measured per episode, the start state of the paper's Barrett protocol, and Table I printed
next to the paper's numbers and the scripted baseline."""

from __future__ import annotations

import ast
import io
import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dgz_cli.sim.evaluate import (CSV_COLUMNS, closing_command, csv_row, hand_reports, palm_object_distance,
                                  run_episodes, summarize)
from dgz_cli.sim.objects import resolve_objects
from dgz_cli.spec.catalog import resolve_spec
from dgz_cli.spec.contract import (MARKOV_GLOBAL_BLOCKS, MARKOV_NODE_BLOCKS, ActionLayout, ClosingPrior,
                                   ControlContract, EpisodeProtocol, ObservationLayout)
from dgz_cli.spec.envconfig import EnvConfig
from dgz_cli.spec.errors import SpecError
from dgz_cli.spec.io import load_spec
from dgz_cli.spec.models import FEATURE_NAMES
from dgz_cli.spec.transform import LENGTH_FEATURES, scale_lengths
from conftest import asset_root, needs_assets

REPO = Path(__file__).resolve().parents[1]
PAPER = Path("/work/shared/paper/dexgrasp-zero.tex")
LINK = [FEATURE_NAMES.index(n) for n in LENGTH_FEATURES]
OTHER = [i for i in range(len(FEATURE_NAMES)) if i not in LINK]
SHORT = EnvConfig(contract=ControlContract(episode=EpisodeProtocol(grasp_steps=8, lift_steps=2, hold_s=0.1)))


@pytest.fixture(scope="module")
def tri():
    return load_spec(resolve_spec("dgz_tri"))


def _bits(values) -> bytes:
    return np.asarray(values, dtype=np.float64).tobytes()


# ------------------------------------------------------------------------------------ scale_lengths
def test_length_features_are_the_link_vector():
    assert LENGTH_FEATURES == ("link_x", "link_y", "link_z") and all(n in FEATURE_NAMES for n in LENGTH_FEATURES)


@pytest.mark.parametrize("s", [2.0, 0.25])
def test_scale_multiplies_exactly_the_length_features(tri, s):
    before = tri.model_dump()
    scaled = scale_lengths(tri, s)
    assert any(row[i] != 0 for row in tri.features.values.values() for i in LINK)  # not vacuous
    assert max(abs(row[i]) for row in tri.features.values.values() for i in LINK) * s < 1  # no clipping here
    for node, row in tri.features.values.items():
        new = scaled.features.values[node]
        assert _bits([new[i] for i in LINK]) == _bits([s * row[i] for i in LINK])
        assert _bits([new[i] for i in OTHER]) == _bits([row[i] for i in OTHER])  # bit-identical
    a, b = scaled.model_dump(), tri.model_dump()
    a["features"].pop("values"), b["features"].pop("values")
    assert a == b  # nothing but the feature values: anchors, palm, M_h, limits, mask, name
    assert tri.model_dump() == before  # the input spec is untouched
    back = scale_lengths(scaled, 1 / s)
    assert _bits([v for row in back.features.values.values() for v in row]) == \
        _bits([v for row in tri.features.values.values() for v in row])


def test_scale_one_is_the_same_spec(tri):
    assert scale_lengths(tri, 1.0) is tri


def test_scaled_features_saturate_like_onboarding():
    allegro = load_spec(resolve_spec("allegro"))
    big = max(((node, i) for node, row in allegro.features.values.items() for i in LINK),
              key=lambda k: abs(allegro.features.values[k[0]][k[1]]))
    v = allegro.features.values[big[0]][big[1]]
    assert 0.5 < abs(v) < 1
    assert scale_lengths(allegro, 2.0).features.values[big[0]][big[1]] == math.copysign(1.0, v)


def test_a_saturated_length_cannot_be_shrunk(tri):
    node = next(iter(tri.features.values))
    row = list(tri.features.values[node])
    row[LINK[0]] = 1.0
    sat = tri.model_copy(update={"features": tri.features.model_copy(
        update={"values": {**tri.features.values, node: row}})})
    with pytest.raises(SpecError, match="saturated"):
        scale_lengths(sat, 0.5)
    assert scale_lengths(sat, 2.0).features.values[node][LINK[0]] == 1.0


@pytest.mark.parametrize("s", [0.0, -1.0, float("nan"), float("inf")])
def test_bad_scale_is_refused(tri, s):
    with pytest.raises(SpecError, match="must be a finite number > 0"):
        scale_lengths(tri, s)


def test_transform_imports_only_the_spec_package():
    tree = ast.parse((REPO / "dgz_cli" / "spec" / "transform.py").read_text())
    mods = [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)] + \
        [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    ours = [m for m in mods if m and m.startswith("dgz_cli")]
    assert ours and all(m.startswith("dgz_cli.spec.") for m in ours), ours


def test_scaled_features_reach_the_policy_and_nothing_else(tri):
    """The policy's `physical` input doubles on the link columns; the simulated hand, its observation and
    its motion under the same actions stay the same."""
    from dgz_cli.sim.env import GraspEnv
    from dgz_cli.sim.scripted import ScriptedGrasp

    sphere = resolve_objects("sphere")[0]
    envs = [GraspEnv([(spec, sphere)], SHORT, threads=1) for spec in (tri, scale_lengths(tri, 2.0))]
    obs = [env.reset(0) for env in envs]
    np.testing.assert_array_equal(obs[1]["physical"][..., LINK], 2 * obs[0]["physical"][..., LINK])
    np.testing.assert_array_equal(obs[1]["physical"][..., OTHER], obs[0]["physical"][..., OTHER])
    policy = ScriptedGrasp(envs[0].N, envs[0].grasp_offset, SHORT.contract)
    for _ in range(4):
        for key in ("nodes", "global", "mask", "adjacency"):
            np.testing.assert_array_equal(obs[0][key], obs[1][key])
        a, b = envs[0].state(), envs[1].state()
        assert all(np.array_equal(a[k], b[k]) for k in a)
        action = policy.act(obs[0])
        obs = [env.step(action)[0] for env in envs]


# ------------------------------------------------------------------------------------ closing onset
class _CloseAt:
    """Zero action until control step ``k``, then ``flex`` on the FLEX column of the nodes in ``nodes``
    (all by default); records the palm distances computed by hand from env.state() at step k."""

    def __init__(self, env, k: int, flex: float = 1.0, nodes: list[int] | None = None) -> None:
        self.env, self.k, self.flex, self.nodes = env, k, flex, nodes
        self.expected: list[tuple[float, float]] = []

    def reset(self, mask=None) -> None:
        pass

    def act(self, obs):
        env = self.env
        act = env.cfg.contract.action
        a = np.zeros((env.B, act.dim(env.N)), np.float32)
        fingers = a[:, act.wrist_dim:].reshape(env.B, env.N, act.n_prim)
        cols = range(env.N) if self.nodes is None else self.nodes
        for b in np.flatnonzero(env.t >= self.k):
            fingers[b, list(cols), 0] = self.flex
        if (env.t == self.k).any():
            st = env.state()
            cloud_w = st["obj_pos"][0] + env.cloud[0] @ st["obj_rot"][0].T  # (P, 3) world surface points
            palm = st["palm_pos"][0]
            self.expected.append((float(np.linalg.norm(cloud_w - palm, axis=1).min()),
                                  float(np.linalg.norm(cloud_w.mean(0) - palm))))
        return a


def _run(spec, k, cfg=SHORT, trials=2, **kw):
    holder = {}

    def make(env):
        holder["p"] = _CloseAt(env, k, **kw)
        return holder["p"]

    records = run_episodes([(spec, resolve_objects("sphere")[0])], make, trials, cfg, threads=1)
    return records, holder["p"]


def test_onset_step_and_distance_match_the_state_by_hand(tri):
    records, policy = _run(tri, 3)
    assert len(records) == 2 and len(policy.expected) == 2
    for r, (surface, center) in zip(records, policy.expected):
        assert r["closing_onset_step"] == 3
        assert r["closing_onset_distance_m"] == pytest.approx(surface, rel=1e-9, abs=1e-12)
        assert r["closing_onset_center_distance_m"] == pytest.approx(center, rel=1e-9, abs=1e-12)
    h = summarize(records)["dgz_tri"]
    assert h["closed_episodes"] == 2 and h["closing_onset_step"] == 3.0
    assert h["closing_onset_distance_m"] == pytest.approx(np.mean([e[0] for e in policy.expected]))
    row = dict(zip(CSV_COLUMNS, csv_row(records[0])))
    assert row["closing_onset_step"] == "3" and float(row["closing_onset_distance_m"]) == \
        pytest.approx(records[0]["closing_onset_distance_m"], abs=5e-5)


def test_onset_at_the_first_step_is_the_start_distance(tri):
    """Closing at once: the palm centre is where the reset put it, approach_distance from the object centre,
    and (a 35 mm sphere) about that minus the radius from its surface."""
    records, _ = _run(tri, 0, trials=1)
    r = records[0]
    assert r["closing_onset_step"] == 0
    assert r["closing_onset_center_distance_m"] == pytest.approx(SHORT.approach_distance, abs=1e-9)
    assert r["closing_onset_distance_m"] == pytest.approx(SHORT.approach_distance - 0.035, abs=0.005)


@pytest.mark.parametrize("kw", [dict(flex=-1.0), dict(nodes=[3, 7, 11])], ids=["opening", "masked-nodes-only"])
def test_no_onset_when_the_fingers_never_close(tri, kw):
    """Opening, or +FLEX only on nodes whose FLEX is inactive (the fingertips), is not closing."""
    records, _ = _run(tri, 0, trials=1, **kw)
    assert records[0]["closing_onset_step"] is None and records[0]["closing_onset_distance_m"] is None
    h = hand_reports(summarize(records))["dgz_tri"]
    assert h["closed_episodes"] == 0 and h["closing_onset_distance_m"] is None
    assert h["objects"]["sphere"]["closing_onset_distance_m"] is None
    assert csv_row(records[0])[-3:] == ["", "", ""]


def test_onset_counts_the_contracts_closing_prior(tri):
    """A zero policy under a closing prior that closes from step 4 closes at step 4: the command is the
    composed one the env applies, not the policy's raw output."""
    lay = ObservationLayout(node=MARKOV_NODE_BLOCKS, global_=MARKOV_GLOBAL_BLOCKS)
    cfg = EnvConfig(contract=ControlContract(observation=lay, prior=ClosingPrior(enabled=True, close_step=4),
                                             episode=SHORT.contract.episode))
    records, _ = _run(tri, 10**6, cfg=cfg, trials=1)
    assert records[0]["closing_onset_step"] == 4


def test_closing_command_by_hand(tri):
    """Mean FLEX over the FLEX-active finger nodes, clipped to [-1, 1]; in the joint action mode the
    sign-corrected mean increment of a node's FLEX joints."""
    from dgz_cli.sim.env import GraspEnv

    sphere = resolve_objects("sphere")[0]
    env = GraspEnv([(tri, sphere), (tri, sphere)], SHORT, threads=1)
    obs = env.reset(0)
    act = SHORT.contract.action
    a = np.zeros((2, act.dim(env.N)))
    fingers = a[:, act.wrist_dim:].reshape(2, env.N, act.n_prim)
    fingers[0, :, 0] = 3.0  # clipped to 1 on each of the 6 active nodes
    fingers[1, 1, 0] = 0.6  # one active node of six
    fingers[1, 3, 0] = 1.0  # a fingertip: FLEX inactive
    np.testing.assert_allclose(closing_command(env, obs, a), [1.0, 0.1])
    surface, center = palm_object_distance(env)
    assert center == pytest.approx([SHORT.approach_distance] * 2, abs=1e-9) and (surface < center).all()

    joint = EnvConfig(contract=ControlContract(action=ActionLayout(mode="joint"), episode=SHORT.contract.episode))
    env = GraspEnv([(tri, sphere)], joint, threads=1)
    obs = env.reset(0)
    a = np.zeros((1, act.dim(env.N)))
    fingers = a[:, act.wrist_dim:].reshape(1, env.N, act.n_prim)
    for j in range(env.L):  # each FLEX joint opens (−sign), the ABD/ROT joints move +1
        node, slot, prim = env.joint_node[0, j], env.joint_slot[0, j], env.joint_prim[0, j]
        fingers[0, node, slot] = -env.joint_sign[0, j] if prim == 0 else 1.0
    np.testing.assert_allclose(closing_command(env, obs, a), [-1.0])


def test_summarize_onset_by_hand():
    base = dict(success=True, unstable=False, touched=True, pushed=False, max_push=0.0, rise_lift_end=0.5,
                max_rise=0.5, return_=1.0)
    recs = [dict(base, hand="h", object="o", trial=0, closing_onset_step=2, closing_onset_distance_m=0.1,
                 closing_onset_center_distance_m=0.2),
            dict(base, hand="h", object="o", trial=1, closing_onset_step=4, closing_onset_distance_m=0.2,
                 closing_onset_center_distance_m=0.3),
            dict(base, hand="h", object="p", trial=0, closing_onset_step=None, closing_onset_distance_m=None,
                 closing_onset_center_distance_m=None),
            dict(base, hand="g", object="o", trial=0)]  # a record without onset fields (older callers)
    s = hand_reports(summarize(recs))
    assert s["h"]["closing_onset_distance_m"] == pytest.approx(0.15)
    assert s["h"]["closing_onset_center_distance_m"] == pytest.approx(0.25)
    assert s["h"]["closing_onset_step"] == 3.0 and s["h"]["closed_episodes"] == 2
    assert s["h"]["objects"]["p"]["closing_onset_distance_m"] is None
    assert s["g"]["closing_onset_distance_m"] is None and s["g"]["closed_episodes"] == 0
    json.dumps(s)  # JSON-ready: None, not NaN


# ------------------------------------------------------------------------------------ the start state
def test_vertical_approach_is_the_barrett_start_state(tri):
    """approach_cone 0: the palm centre starts approach_distance straight above the object centre, the palm
    normal pointing down, every joint at zero (the paper's Barrett protocol: 0.30 m above, joints zero)."""
    from dgz_cli.sim.env import GraspEnv

    cfg = SHORT.model_copy(update=dict(approach_cone=0.0))
    env = GraspEnv([(tri, o) for o in resolve_objects("sphere,box")], cfg, threads=1)
    env.reset(3)
    st = env.state()
    center = st["obj_pos"] + np.einsum("bij,bj->bi", st["obj_rot"], env.cloud_sum) / env.cloud.shape[1]
    # (to < 2 mm: the reset aims at the object centre of the settle's last physics step, and a box may still
    # move in it; a sphere at rest is exact, see test_onset_at_the_first_step_is_the_start_distance)
    np.testing.assert_allclose(st["palm_pos"] - center, [[0, 0, 0.3]] * 2, atol=2e-3)
    np.testing.assert_allclose(st["palm_rot"][:, :, 2], [[0, 0, -1]] * 2, atol=1e-9)
    assert np.abs(st["q"]).max() < 1e-12 and (tri.rest_pose() == 0).all()
    assert (load_spec(resolve_spec("barrett")).rest_pose() == 0).all()  # Barrett's open hand is all zeros
    assert EnvConfig().approach_cone == 0.5 and EnvConfig().approach_distance == 0.3  # the default stays tilted


# ------------------------------------------------------------------------------------ Table I
def _report(path: Path, policy: str, training: list[str], rates: dict[str, float]) -> Path:
    path.write_text(json.dumps({"policy": policy, "training_hands": training,
                                "hands": {h: {"success_rate": r, "episodes": 10} for h, r in rates.items()}}))
    return path


def _table(files, paper=None) -> str:
    from rich.console import Console

    from dgz_cli.cli.eval_table import render_table

    buf = io.StringIO()
    assert render_table(files, Console(file=buf, width=120, emoji=False), paper) == 0
    return buf.getvalue()


def test_table_shows_the_paper_and_the_scripted_baseline(tmp_path):
    from dgz_cli.cli.eval_table import PAPER_TABLE_I

    ours = _report(tmp_path / "full.json", "runs/full", ["allegro", "shadow", "ability", "schunk_svh"],
                   {"allegro": 0.5, "shadow": 0.25, "ability": 0.75, "schunk_svh": 1.0, "leap": 0.125})
    base = _report(tmp_path / "base.json", "scripted", [], {"allegro": 0.25, "leap": 0.5, "inspire": 0.25})
    text = _table([ours, base])
    lines = text.splitlines()
    full = next(line for line in lines if "paper: DexGrasp-Zero (full model)" in line)
    assert re.findall(r"\d\.\d+", full) == ["0.92", "0.95", "0.90", "0.91", "0.93", "0.82", "0.92", "0.85"]
    assert sum("paper:" in line for line in lines) == len(PAPER_TABLE_I) == 7
    assert "Table I (tab:cross)" in text
    header = next(line for line in lines if "allegro (train)" in line)
    assert header.index("allegro") < header.index("shadow") < header.index("ability") < header.index("schunk_svh") \
        < header.index("leap (unseen)") < header.index("inspire (unseen)")  # the paper's column order
    mine = next(line for line in lines if "full (runs/full)" in line)
    # the averages are over the hands both files have (allegro; leap), not each file's own (0.625; 0.375)
    assert re.findall(r"\d\.\d+", mine) == ["0.50", "0.25", "0.75", "1.00", "0.12", "0.500", "0.125"]
    scripted = next(line for line in lines if "base (scripted baseline)" in line)
    assert re.findall(r"\d\.\d+", scripted) == ["0.25", "0.50", "0.25", "0.250", "0.500"]
    assert "averages are over the hands every file has: seen allegro; unseen leap" in text
    assert "paper:" not in _table([ours, base], paper=False)


def test_table_averages_every_hand_when_the_files_agree(tmp_path):
    rates = {"allegro": 0.5, "shadow": 0.25, "leap": 0.75, "inspire": 0.25}
    a = _report(tmp_path / "a.json", "runs/a", ["allegro", "shadow"], rates)
    b = _report(tmp_path / "b.json", "scripted", [], {h: r / 2 for h, r in rates.items()})
    text = _table([a, b], paper=False)
    assert "every file has" not in text
    row_a = next(line for line in text.splitlines() if "a (runs/a)" in line)
    row_b = next(line for line in text.splitlines() if "b (scripted baseline)" in line)
    assert re.findall(r"\d\.\d+", row_a)[-2:] == ["0.375", "0.500"]
    assert re.findall(r"\d\.\d+", row_b)[-2:] == ["0.188", "0.250"]


def test_table_paper_rows_only_with_the_papers_hands(tmp_path):
    tri_only = _report(tmp_path / "t.json", "runs/t", ["dgz_tri"], {"dgz_tri": 0.5})
    assert "paper:" not in _table([tri_only]) and "dgz_tri (train)" in _table([tri_only])
    text = _table([tri_only], paper=True)
    assert "paper: CrossDex (per-object)" in text and "leap (unseen)" in text
    single = _report(tmp_path / "s.json", "runs/s", ["allegro"], {"allegro": 0.5, "leap": 0.5})
    assert "split differs from the paper's for shadow (ours: unseen, paper: train)" in _table([single])


def test_table_by_object_puts_the_hardest_object_first(tmp_path):
    from rich.console import Console

    from dgz_cli.cli.eval_table import render_object_table

    def report(name: str, rates: dict[str, dict[str, float]]) -> Path:
        hands = {h: {"success_rate": sum(o.values()) / len(o), "episodes": 4 * len(o),
                     "objects": {k: {"success_rate": v, "trials": 4} for k, v in o.items()}} for h, o in rates.items()}
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"policy": name, "training_hands": ["allegro"], "hands": hands}))
        return path

    a = report("a", {"allegro": {"box": 1.0, "knife": 0.25}, "leap": {"box": 0.5, "knife": 0.0}})
    b = report("b", {"allegro": {"box": 0.25, "knife": 0.75}})

    def render(files) -> list[str]:
        buf = io.StringIO()
        assert render_object_table(files, Console(file=buf, width=120, emoji=False)) == 0
        return buf.getvalue().splitlines()

    lines = render([a])
    rows = [line for line in lines if "knife" in line or "box" in line]
    assert "knife" in rows[0] and "box" in rows[1]  # knife's mean 0.125 < box's 0.75
    assert re.findall(r"\d\.\d+", rows[0]) == ["0.25", "0.00", "0.125"]  # allegro, leap, mean over hands
    assert re.findall(r"\d\.\d+", next(line for line in lines if "mean over objects" in line)) == ["0.62", "0.25", "0.438"]
    both = render([a, b])  # the first file's order; each file's mean over its hands
    assert re.findall(r"\d\.\d+", next(line for line in both if "knife" in line)) == ["0.125", "0.750"]


def test_table_by_object_refuses_a_file_without_objects(tmp_path):
    f = _report(tmp_path / "r.json", "runs/r", [], {"leap": 0.5})
    res = _dgz("eval", "--table", str(f), "--by-object", cwd=tmp_path)
    assert res.returncode == 1 and "Traceback" not in res.stderr
    assert "r.json: no per-object results (field 'hands.leap.objects')" in " ".join(res.stderr.split())


@pytest.mark.skipif(not PAPER.is_file(), reason="the paper's .tex is not on this machine")
def test_paper_numbers_are_quoted_exactly():
    from dgz_cli.cli.eval_table import PAPER_HANDS, PAPER_TABLE_I

    tex = PAPER.read_text()
    block = tex[tex.index(r"\label{tab:cross}"):tex.index(r"\end{tabular}", tex.index(r"\label{tab:cross}"))]
    header = next(line for line in block.splitlines() if "Allegro" in line and "&" in line)
    assert [c.strip() for c in header.split("&")][2:8] == [p for p, _ in PAPER_HANDS]
    rows = []
    for line in block.splitlines():
        cells = [re.sub(r"\\textbf\{([^}]*)\}", r"\1", c).strip().rstrip("\\").strip()
                 for c in re.split(r"(?<!\\)&", line)]  # a "\&" inside a variant name is not a column
        if len(cells) == 10 and re.fullmatch(r"\d\.\d+", cells[2]):
            rows.append(cells[2:])
    assert rows == [[*p.rates.values(), p.seen, p.unseen] for p in PAPER_TABLE_I]


def test_table_from_the_command_line(tmp_path):
    f = _report(tmp_path / "r.json", "scripted", [], {"leap": 0.5})
    res = subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", "eval", "--table", str(f)], cwd=tmp_path,
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "paper: DexGrasp-Zero (full model)" in res.stdout and "r (scripted baseline)" in res.stdout


# ------------------------------------------------------------------------------------ dgz eval options
def _dgz(*args, cwd):
    return subprocess.run([sys.executable, "-m", "dgz_cli.cli.app", *args], cwd=cwd, capture_output=True, text=True)


def test_eval_records_feature_scale_start_state_and_onset(tmp_path):
    js, cs = tmp_path / "r.json", tmp_path / "r.csv"
    res = _dgz("eval", "--hand", "dgz_tri", "--objects", "sphere", "--trials", "1", "--feature-scale", "2",
               "--approach-cone", "0", "--json", str(js), "--csv", str(cs), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    data = json.loads(js.read_text())
    assert data["protocol"]["feature_scale"] == 2.0
    assert data["protocol"]["approach_cone_rad"] == 0.0 and data["protocol"]["approach_distance_m"] == 0.3
    hand = data["hands"]["dgz_tri"]
    assert hand["closed_episodes"] == 1 and 0 < hand["closing_onset_distance_m"] < 0.3
    rows = cs.read_text().splitlines()
    assert rows[0] == ",".join(CSV_COLUMNS) and len(rows) == 2 and rows[1].split(",")[-3] != ""
    assert data["protocol"]["physics_hz"] == 400.0


def test_eval_physics_hz_sets_the_scripted_env(tmp_path):
    """The physics_hz ±0.03 check (issue 11, lever 9) evaluates the scripted grasp at a lower physics rate: the
    rate reaches the simulator and the record, and the result differs from 400 Hz (same start states)."""
    out = {}
    for hz in ("400", "100"):
        js = tmp_path / f"{hz}.json"
        res = _dgz("eval", "--hand", "dgz_tri", "--objects", "sphere", "--trials", "2", "--physics-hz", hz,
                   "--csv", str(tmp_path / f"{hz}.csv"), "--json", str(js), cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        out[hz] = json.loads(js.read_text())
        assert out[hz]["protocol"]["physics_hz"] == float(hz)
    rows = {hz: (tmp_path / f"{hz}.csv").read_text().splitlines()[1:] for hz in out}
    assert rows["400"] != rows["100"]  # another physics step gives other trajectories


@needs_assets()
def test_eval_thumb_open_sets_the_scripted_start_pose(tmp_path):
    """`--thumb-open` (issue 11, E11) starts the scripted grasp from the contract's thumb-open pose: recorded in
    the protocol, and other trajectories than the flat open hand's on the same start states (the Inspire's
    thumb yaw is its ABD joint, at rest 0 and +ABD limit 1.308 rad)."""
    out = {}
    for f in ("0", "1"):
        js = tmp_path / f"{f}.json"
        res = _dgz("eval", "--hand", "inspire", "--objects", "sphere", "--trials", "2", "--thumb-open", f,
                   "--asset-root", str(asset_root().resolve()),
                   "--csv", str(tmp_path / f"{f}.csv"), "--json", str(js), cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        out[f] = json.loads(js.read_text())
        assert out[f]["protocol"]["thumb_open"] == float(f) and out[f]["protocol"]["thumb_open_primitives"] == ["ABD"]
    rows = {f: (tmp_path / f"{f}.csv").read_text().splitlines()[1:] for f in out}
    assert rows["0"] != rows["1"]


def test_eval_guidance_stop_gap_is_recorded_and_changes_the_scripted_grasp(tmp_path):
    """`--guidance-stop-gap` (issue 11): the guidance stops pressing the palm along its normal near the surface;
    recorded in the protocol, and other trajectories than the guidance that presses on."""
    rows, gaps = {}, {}
    for extra in ((), ("--guidance-stop-gap", "0.1")):
        js, csv = tmp_path / f"{len(extra)}.json", tmp_path / f"{len(extra)}.csv"
        res = _dgz("eval", "--hand", "dgz_tri", "--objects", "box", "--trials", "2", "--guidance", "0.05", *extra,
                   "--json", str(js), "--csv", str(csv), cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        gaps[extra] = json.loads(js.read_text())["protocol"]["guidance_stop_gap_m"]
        rows[extra] = csv.read_text().splitlines()[1:]
    assert gaps == {(): None, ("--guidance-stop-gap", "0.1"): 0.1}
    assert rows[()] != rows[("--guidance-stop-gap", "0.1")]


def test_eval_roll_is_a_start_state_option_for_checkpoints_too(tmp_path):
    """Like --approach-cone, --roll sets the start state of a checkpoint's evaluation (default: its own)."""
    rolls = {}
    for extra in ((), ("--roll", "clear")):
        js = tmp_path / f"{len(extra)}.json"
        res = _dgz("eval", "--policy", "dgz-cpu-thumb-open", "--hand", "dgz_tri", "--objects", "sphere", "--trials",
                   "1", *extra, "--json", str(js), cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        rolls[extra] = json.loads(js.read_text())["protocol"]["roll"]
    assert rolls == {(): "narrow", ("--roll", "clear"): "clear"}


def _scripted_box_runs(tmp_path: Path, option: tuple[str, ...], field: str) -> tuple[dict, dict]:
    """Scripted `dgz eval` on dgz_tri × box (2 trials) without and with ``option``: per run (keyed by the extra
    arguments), the JSON protocol's ``field`` and the CSV's episode rows."""
    recorded, rows = {}, {}
    for extra in ((), option):
        js, csv = tmp_path / f"{len(extra)}.json", tmp_path / f"{len(extra)}.csv"
        res = _dgz("eval", "--hand", "dgz_tri", "--objects", "box", "--trials", "2", *extra, "--json", str(js),
                   "--csv", str(csv), cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        recorded[extra] = json.loads(js.read_text())["protocol"][field]
        rows[extra] = csv.read_text().splitlines()[1:]
    return recorded, rows


def _checkpoint_protocol(tmp_path: Path, option: tuple[str, ...], field: str):
    """The JSON protocol's ``field`` of one `dgz-cpu-thumb-open` episode on dgz_tri × sphere run with ``option``."""
    js = tmp_path / "ckpt.json"
    res = _dgz("eval", "--policy", "dgz-cpu-thumb-open", "--hand", "dgz_tri", "--objects", "sphere", "--trials", "1",
               *option, "--json", str(js), cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    return json.loads(js.read_text())["protocol"][field]


def test_eval_settle_is_a_start_state_option_recorded_in_the_protocol(tmp_path):
    """`--settle` (issue 12: the held first frame must show an object at rest) sets how long the dropped object
    settles before the first frame, for checkpoints too: recorded, and a box dropped in a random orientation
    starts elsewhere after 2 s than after the default 0.3 s, so the trajectories differ."""
    settles, rows = _scripted_box_runs(tmp_path, ("--settle", "2"), "settle_s")
    assert settles == {(): 0.3, ("--settle", "2"): 2.0}
    assert rows[()] != rows[("--settle", "2")]
    assert _checkpoint_protocol(tmp_path, ("--settle", "1.5"), "settle_s") == 1.5


def test_upright_objects_keep_their_model_frame_up_and_only_the_yaw_varies(tri):
    """object_orientation 'upright' (GraspXL's and RobustDexGrasp's placement): the object starts in its model's
    frame, z up, turned about the vertical by a random yaw; 'random' (the default) tilts it anywhere."""
    from dgz_cli.sim.env import GraspEnv

    box = resolve_objects("box")[0]
    rot = {}
    for orientation in ("random", "upright"):
        env = GraspEnv([(tri, box)] * 6, EnvConfig(object_orientation=orientation), seed=5, threads=1)
        env.reset(1)
        rot[orientation] = env.state()["obj_rot"]
    tilt = {k: r[:, 2, 2] for k, r in rot.items()}  # cosine between the object's z axis and world z
    np.testing.assert_allclose(tilt["upright"], 1.0, atol=1e-3)  # a flat box stays flat on the table
    assert np.ptp(np.arctan2(rot["upright"][:, 1, 0], rot["upright"][:, 0, 0])) > 0.5  # ... at different yaws
    assert (tilt["random"] < 0.99).sum() >= 3  # dropped anyhow, most boxes land on another face
    assert EnvConfig().object_orientation == "random"


def test_eval_object_orientation_is_a_start_state_option_for_checkpoints_too(tmp_path):
    """`--object-orientation` is recorded in the protocol, changes the episodes, and applies to a checkpoint."""
    upright = ("--object-orientation", "upright")
    recorded, rows = _scripted_box_runs(tmp_path, upright, "object_orientation")
    assert recorded == {(): "random", upright: "upright"}
    assert rows[()] != rows[upright]
    assert _checkpoint_protocol(tmp_path, upright, "object_orientation") == "upright"


@pytest.mark.parametrize("args,message", [
    (("--settle", "-1"), "--settle"),
    (("--settle", "nan"), "--settle"),
    (("--settle", "11"), "--settle"),
    (("--feature-scale", "0"), "--feature-scale"),
    (("--feature-scale", "nan"), "--feature-scale"),
    (("--approach-cone", "-0.1"), "--approach-cone"),
    (("--approach-cone", "2"), "--approach-cone"),
    (("--physics-hz", "250"), "--physics-hz"),  # not a whole number of physics steps per 20 Hz control step
    (("--physics-hz", "0"), "--physics-hz"),
    (("--physics-hz", "-400"), "--physics-hz"),
    (("--guidance", "1.5"), "--guidance"),  # a gain, in [0, 1]
    (("--guidance", "-0.05"), "--guidance"),
    (("--policy", "dgz-cpu-residual", "--physics-hz", "200"), "--physics-hz"),  # a checkpoint runs its own
    (("--thumb-open", "1.5"), "--thumb-open"),  # a fraction of the thumb's opening range
    (("--thumb-open", "-1"), "--thumb-open"),
    (("--policy", "dgz-cpu-residual", "--thumb-open", "1"), "--thumb-open"),
    (("--roll", "sideways"), "--roll"),
    (("--object-orientation", "sideways"), "--object-orientation"),
    (("--guidance-stop-gap", "0.05"), "--guidance-stop-gap"),  # without --guidance there is nothing to stop
    (("--guidance", "0.05", "--guidance-stop-gap", "0"), "--guidance-stop-gap"),
    (("--guidance", "0.05", "--guidance-stop-gap", "0.4"), "--guidance-stop-gap"),
    (("--policy", "dgz-cpu-residual", "--guidance-stop-gap", "0.05"), "--guidance-stop-gap"),
])
def test_eval_refuses_bad_protocol_options(tmp_path, args, message):
    res = _dgz("eval", "--hand", "dgz_tri", "--objects", "sphere", "--trials", "1", *args, cwd=tmp_path)
    assert res.returncode != 0 and message in res.stderr and "Traceback" not in res.stderr
