"""Onboarding vs the ground truth of generated hands (`dgz hands check`, tests/test_hand_generator.py).

For each hand: onboard it and lint the result exactly as `dgz onboard` does, then compare every actuated
joint's (primitive, sign, node type) and, where the hand has a canonical naming, its finger class with the
labels written by :mod:`dgz_cli.onboard.generate`. Outcomes:

- ``agree``: lint passes and every label is recovered;
- ``refused``: onboarding stopped with a clear error, or lint refused a spec that was indeed wrong;
- ``wrong``: lint passed but some label differs (a wrong spec that lints clean — must never happen);
- ``false_refusal``: lint refused a spec whose labels were all right (must never happen).

Independently, the spec forced to the ground truth (every joint overridden to its label) must pass the
functional check: ``truth_refused`` counts hands where lint would refuse the correct answer.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from dgz_cli.onboard.generate import HandLabels, load_labels
from dgz_cli.spec.errors import DgzError
from dgz_cli.spec.models import Overrides

OUTCOMES = ("agree", "refused", "wrong", "false_refusal")


@dataclass
class HandCheck:
    name: str
    kind: str
    outcome: str
    mismatches: list[str] = field(default_factory=list)
    error: str | None = None
    truth_problems: list[str] = field(default_factory=list)
    seconds: float = 0.0


def _lint(result) -> list[str]:
    from dgz_cli.onboard.verify import verify_against_urdf
    from dgz_cli.spec.lint import lint_spec

    spec = result.spec
    findings = lint_spec(spec) + verify_against_urdf(spec, Path("generated.yaml"), None, result.poser)
    return [f.message for f in findings if f.level == "error"]


def compare(spec, labels: HandLabels) -> list[str]:
    """Every way ``spec`` differs from the ground truth (empty = agreement)."""
    rows = {r.joint: r for r in spec.joints}
    nodes = {n.id: n for n in spec.nodes}
    out = []
    for lab in labels.joints:
        r = rows.get(lab.joint)
        if r is None:
            out.append(f"{lab.joint}: not in M_h")
            continue
        node = nodes[r.node]
        if (r.primitive.value, r.sign) != (lab.primitive, lab.sign):
            out.append(f"{lab.joint}: {r.primitive.value} {r.sign:+d}, truth {lab.primitive} {lab.sign:+d}")
        if node.type != lab.node_type:
            out.append(f"{lab.joint}: node type {node.type}, truth {lab.node_type}")
        if lab.finger_class is not None and node.finger != lab.finger_class:
            out.append(f"{lab.joint}: finger {node.finger}, truth {lab.finger_class}")
    if labels.side is not None and spec.palm.side != labels.side:
        out.append(f"side {spec.palm.side}, truth {labels.side}")
    by_finger: dict[str, set[str]] = {}
    for lab in labels.joints:
        if lab.joint in rows:
            by_finger.setdefault(lab.finger, set()).add(nodes[rows[lab.joint].node].finger)
    classes = [next(iter(v)) for v in by_finger.values() if len(v) == 1]
    if any(len(v) > 1 for v in by_finger.values()) or len(set(classes)) != len(classes):
        out.append("the joints of one generated finger are not one finger of the spec")
    return out


def _truth_overrides(labels: HandLabels) -> Overrides:
    return Overrides.model_validate({"joints": {lab.joint: {"primitive": lab.primitive, "sign": lab.sign,
                                                            "reason": "ground truth of the generated hand"}
                                                for lab in labels.joints}})


def check_one(urdf: Path, labels: HandLabels, truth_lint: bool = True) -> HandCheck:
    from dgz_cli.onboard.pipeline import onboard

    t0 = time.perf_counter()
    res = HandCheck(labels.name, labels.kind, "refused")
    try:
        result = onboard(urdf, "generated")
    except DgzError as exc:
        res.error = exc.message
        res.seconds = time.perf_counter() - t0
        return res
    mismatches = compare(result.spec, labels)
    errors = _lint(result)
    res.mismatches = mismatches
    if errors:
        res.error = errors[0]
        res.outcome = "false_refusal" if not mismatches else "refused"
    else:
        res.outcome = "wrong" if mismatches else "agree"
    if truth_lint:
        if mismatches:
            try:
                truth = onboard(urdf, "generated", overrides=_truth_overrides(labels))
                res.truth_problems = _lint(truth)
            except DgzError as exc:
                res.truth_problems = [exc.message]
        else:
            res.truth_problems = errors
    res.seconds = time.perf_counter() - t0
    return res


def check_dir(folder: Path, truth_lint: bool = True) -> list[HandCheck]:
    out = []
    for lab in sorted(folder.glob("*.labels.json")):
        labels = load_labels(lab)
        out.append(check_one(folder / f"{labels.name}.urdf", labels, truth_lint))
    return out


def summary(checks: list[HandCheck]) -> dict:
    n = len(checks)
    counts = {o: sum(c.outcome == o for c in checks) for o in OUTCOMES}
    kinds = sorted({c.kind for c in checks})
    return dict(
        hands=n, **counts,
        agreement=round(counts["agree"] / max(n, 1), 4),
        refusal_rate=round(counts["refused"] / max(n, 1), 4),
        truth_refused=sum(bool(c.truth_problems) for c in checks),
        by_kind={k: {o: sum(c.outcome == o for c in checks if c.kind == k) for o in OUTCOMES} for k in kinds},
        seconds_per_hand=round(float(np.mean([c.seconds for c in checks])) if checks else 0.0, 4),
        failures=[asdict(c) for c in checks if c.outcome in ("wrong", "false_refusal") or c.truth_problems],
    )
