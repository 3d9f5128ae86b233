"""The procedural hand generator (issue 13): deterministic by seed, labels that match the construction (checked
here by forward kinematics alone, never by the onboarding), and onboarding's agreement with those labels over
a fixed batch: it recovers the ground truth or refuses with a one-line error; it never writes a wrong spec that
lints clean, and lint never refuses the ground truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dgz_cli.onboard.agreement import check_dir, summary
from dgz_cli.onboard.compile import Poser, compile_model
from dgz_cli.onboard.generate import generate_one, load_labels, write_hands
from dgz_cli.onboard.urdf import load_kinematics

SEEDS = (101, 202, 303, 404)  # the CI batch: 4 × 60 = 240 hands
PER_SEED = 60


def test_generation_is_deterministic_by_seed(tmp_path):
    a = [generate_one(11, i) for i in range(25)]
    assert a == [generate_one(11, i) for i in range(25)]
    assert [t for t, _, _ in a] != [generate_one(12, i)[0] for i in range(25)]
    write_hands(tmp_path / "x", 11, 6)
    write_hands(tmp_path / "y", 11, 6)
    for f in sorted((tmp_path / "x").rglob("*.*")):
        assert f.read_bytes() == (tmp_path / "y" / f.relative_to(tmp_path / "x")).read_bytes(), f.name
    kinds = {labels.kind for _, labels, _ in (generate_one(11, i) for i in range(80))}
    assert kinds == {"hand", "claw", "opposed", "jaw"}


def _distal(poser: Poser, kin, chain_joint: str) -> np.ndarray:
    """Centre of the collision geometry of the last link of the chain that ``chain_joint`` belongs to."""
    link = kin.joints[chain_joint].child
    while (kids := [j for j in kin.children(link) if j.movable]):
        link = kids[0].child
    return poser.geom_points([link]).mean(0)


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    folder = tmp_path_factory.mktemp("generated")
    for seed in SEEDS:
        write_hands(folder, seed, PER_SEED)
    return folder


def test_labels_match_the_construction(batch):
    """Every actuated joint has one label, mimic joints none; and moving a joint by +sign does what its label
    says in the hand's own geometry: FLEX closes (toward the palm side, or the grasp axis of claws and jaws),
    finger ABD moves away from the middle finger, thumb ABD opens the thumb-finger angle."""
    checked = {"FLEX": 0, "ABD": 0}
    for lab_path in sorted(batch.glob("gen_101_*.labels.json"))[:40]:
        labels = load_labels(lab_path)
        kin = load_kinematics(batch / f"{labels.name}.urdf")
        actuated = {j.name for j in kin.actuated}
        assert {lab.joint for lab in labels.joints} == actuated, labels.name
        assert set(labels.mimic) == {j.name for j in kin.joints.values() if j.mimic is not None}
        poser = Poser(kin, compile_model(kin))
        rest = poser.rest()
        poser.pose(rest)
        palm = poser.link_pos("palm")
        f = np.array(labels.finger_axis)
        n = np.array(labels.palm_normal) if labels.palm_normal is not None else None
        first = {lab.finger: next(l.joint for l in labels.joints if l.finger == lab.finger and l.node == 0)
                 for lab in labels.joints}
        base = {fing: poser.joint_anchor(j) for fing, j in first.items()}
        cls = {lab.finger: lab.finger_class for lab in labels.joints}
        for lab in labels.joints:
            poser.pose(rest)
            before = _distal(poser, kin, lab.joint)
            step = 0.01 if kin.joints[lab.joint].type == "prismatic" else 0.05
            poser.pose({**rest, lab.joint: rest[lab.joint] + lab.sign * step})
            after = _distal(poser, kin, lab.joint)
            move = after - before
            if lab.primitive == "FLEX":
                if n is not None:
                    toward = n
                else:
                    off = (before - palm) - ((before - palm) @ f) * f
                    toward = -off / np.linalg.norm(off)
                assert move @ toward > 0, (labels.name, lab.joint)
                checked["FLEX"] += 1
            elif lab.primitive == "ABD" and lab.finger_class != "thumb":
                lateral = np.cross(n, f)
                mid = next(k for k, c in cls.items() if c == "middle")
                thumb = next((k for k, c in cls.items() if c == "thumb"), None)
                if lab.finger == mid:
                    away = (base[thumb] - base[mid]) @ lateral if thumb else 1.0
                else:
                    away = (base[lab.finger] - base[mid]) @ lateral
                assert (move @ lateral) * np.sign(away) > 0, (labels.name, lab.joint)
                checked["ABD"] += 1
            elif lab.primitive == "ABD":
                root = poser.joint_anchor(first[lab.finger])
                angle = [np.arccos(np.clip((p - root) @ f / np.linalg.norm(p - root), -1, 1)) for p in (before, after)]
                assert angle[1] > angle[0], (labels.name, lab.joint)
                checked["ABD"] += 1
    assert checked["FLEX"] > 100 and checked["ABD"] > 20


def test_onboarding_agrees_with_the_generated_ground_truth(batch):
    """At least 200 hands: no wrong spec lints clean, lint refuses no correct spec nor any ground truth, every
    refusal is one clear line, and onboarding recovers (almost) every hand."""
    checks = check_dir(batch)
    result = summary(checks)
    assert result["hands"] == len(SEEDS) * PER_SEED >= 200
    assert result["wrong"] == 0, json.dumps(result["failures"][:3], indent=1)
    assert result["false_refusal"] == 0, json.dumps(result["failures"][:3], indent=1)
    assert result["truth_refused"] == 0, json.dumps(result["failures"][:3], indent=1)
    assert result["agreement"] >= 0.95, result
    for c in checks:
        if c.outcome == "refused":
            assert c.error and "\n" not in c.error and ":" in c.error, c.error
    for kind in ("hand", "claw", "opposed", "jaw"):
        assert result["by_kind"][kind]["agree"] > 0, kind
