"""`dgz eval --table`: the schema of a `dgz eval --json` result file as the table reads it (finite, bounded
fields), the paper's Table I numbers, and the table itself (ours next to the paper's and the scripted baseline)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from dgz_cli.spec.errors import DgzError

MAX_TABLE_BYTES = 16 * 1024 * 1024
_Name = Annotated[str, Field(min_length=1, max_length=200)]


_Rate = Annotated[float, Field(allow_inf_nan=False, ge=0.0, le=1.0)]


class ObjectResult(BaseModel):
    model_config = ConfigDict(extra="allow")

    success_rate: _Rate
    trials: Annotated[int, Field(ge=0, le=10**9)] = 0


class HandResult(BaseModel):
    model_config = ConfigDict(extra="allow")

    success_rate: _Rate
    episodes: Annotated[int, Field(ge=0, le=10**9)] = 0
    objects: dict[_Name, ObjectResult] = Field(default_factory=dict, max_length=100000)


class EvalReport(BaseModel):
    model_config = ConfigDict(extra="allow")

    policy: _Name = "?"
    training_hands: list[_Name] = Field(default_factory=list, max_length=1000)
    hands: dict[_Name, HandResult] = Field(max_length=1000)


def load_eval_report(path: Path) -> EvalReport:
    """One `dgz eval --json` file, or a one-line :class:`DgzError` naming the file and the field."""
    from dgz_cli.spec.io import read_text_bounded

    hint = "pass files written by `dgz eval ... --json FILE`"
    text = read_text_bounded(Path(path), MAX_TABLE_BYTES, DgzError)
    try:
        data = json.loads(text)
    except (ValueError, RecursionError):
        raise DgzError(f"{path}: not JSON (not a `dgz eval --json` result)", hint) from None
    if not isinstance(data, dict):
        raise DgzError(f"{path}: not a `dgz eval --json` result (top level must be an object)", hint)
    try:
        return EvalReport.model_validate(data)
    except ValidationError as exc:
        e = exc.errors()[0]
        loc = ".".join(str(p) for p in e["loc"]) or "(top level)"
        raise DgzError(f"{path}: field '{loc}': {e['msg']}", hint) from None


# ------------------------------------------------------------------------------------------------------------
# The paper's Table I, as data: the one place its numbers live.
# Source: the DexGrasp-Zero paper (shared/paper/dexgrasp-zero.tex), Table I, \label{tab:cross}, caption
# "Cross-embodiment training and zero-shot transfer results (success rate)". Cells are quoted exactly as
# printed (strings; bold dropped), averages included (the paper's own "Seen"/"Unseen" columns).
# ------------------------------------------------------------------------------------------------------------

PAPER_TABLE_NAME = ("DexGrasp-Zero paper, Table I (tab:cross): \"Cross-embodiment training and zero-shot transfer "
                    "results (success rate)\"")
# the paper's column → our shipped hand name, in the paper's column order
PAPER_HANDS: tuple[tuple[str, str], ...] = (("Allegro", "allegro"), ("Shadow", "shadow"), ("Ability", "ability"),
                                            ("Schunk", "schunk_svh"), ("LEAP", "leap"), ("Inspire", "inspire"))
PAPER_TRAINING_HANDS = ("allegro", "shadow", "ability", "schunk_svh")
PAPER_UNSEEN_HANDS = ("leap", "inspire")


class PaperRow(BaseModel):
    """One row of the paper's Table I: ``rates`` per hand (our names), ``seen``/``unseen`` its averages;
    ``ablation``: the `dgz train --ablation` variant that reproduces it (None: another method)."""

    model_config = ConfigDict(frozen=True)

    method: str
    variant: str
    ablation: str | None
    rates: dict[str, str]
    seen: str
    unseen: str


def _row(method: str, variant: str, ablation: str | None, *cells: str) -> PaperRow:
    rates = dict(zip((h for _, h in PAPER_HANDS), cells[:6], strict=True))
    return PaperRow(method=method, variant=variant, ablation=ablation, rates=rates, seen=cells[6], unseen=cells[7])


PAPER_TABLE_I: tuple[PaperRow, ...] = (
    _row("CrossDex", "per-object", None, "0.81", "0.85", "0.90", "0.90", "0.34", "0.44", "0.865", "0.39"),
    _row("CrossDex", "multi-object", None, "0.39", "0.69", "0.42", "0.60", "0.19", "0.34", "0.525", "0.265"),
    _row("DexGrasp-Zero", "w/o motion primitives", "no_primitives",
         "0.52", "0.51", "0.64", "0.59", "0.39", "0.29", "0.565", "0.34"),
    _row("DexGrasp-Zero", "early fusion", "early_fusion",
         "0.42", "0.47", "0.59", "0.54", "0.46", "0.34", "0.505", "0.40"),
    _row("DexGrasp-Zero", "w/o G_physical priors", "no_physical",
         "0.91", "0.89", "0.90", "0.84", "0.82", "0.79", "0.885", "0.805"),
    _row("DexGrasp-Zero", "w/o M_activation & r_pen", "no_mask",
         "0.92", "0.91", "0.90", "0.81", "0.50", "0.76", "0.885", "0.63"),
    _row("DexGrasp-Zero", "full model", "full", "0.92", "0.95", "0.90", "0.91", "0.93", "0.82", "0.92", "0.85"),
)


def _column_order(hand: str) -> tuple[int, str]:
    """The paper's hands first, in its column order, then the others by name."""
    names = [h for _, h in PAPER_HANDS]
    return (names.index(hand), "") if hand in names else (len(names), hand)


def render_table(files: list[Path], console, paper: bool | None = None) -> int:
    """Print Table I from `dgz eval --json` files (``console``: a rich Console): one row per file, columns
    training hands | unseen hands | seen and unseen averages. The split is the files' own (a hand is a
    training column when any file's policy trained on it), or the paper's when only baselines (no training
    hands) are given. A `--policy scripted` file is labelled the scripted baseline. Every row's averages are
    over the same hands, those that every file has (a note names them when a file has more), so that the
    rows compare.

    ``paper``: also print the paper's Table I rows (:data:`PAPER_TABLE_I`, quoted) above ours, with its
    hands as columns; None = when any file has one of the paper's hands. A note names any hand whose split
    differs from the paper's. Returns the exit code (0)."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    rows = []
    for f in files:
        rep = load_eval_report(Path(f))  # schema-checked: a bad file is one line naming the file and field
        rows.append((Path(f).stem, rep.policy, set(rep.training_hands),
                     {h: r.model_dump() for h, r in rep.hands.items()}))
    present = {h for *_, hs in rows for h in hs}
    paper_names = {h for _, h in PAPER_HANDS}
    show_paper = bool(present & paper_names) if paper is None else paper
    trained = set().union(*(tr for _, _, tr, _ in rows))  # the protocol's split: any policy's training hands
    columns = present | (paper_names if show_paper else set())
    if not trained:  # baselines only: the paper's split for its hands
        trained = set(PAPER_TRAINING_HANDS)
    seen_cols = sorted((h for h in columns if h in trained), key=_column_order)
    unseen_cols = sorted((h for h in columns if h not in trained), key=_column_order)
    cols = seen_cols + unseen_cols
    t = Table(title="success rate (Table I layout: training hands | unseen hands | averages)")
    t.add_column("policy", no_wrap=True)
    for h in seen_cols:
        t.add_column(f"{escape(str(h))} (train)", justify="right")
    for h in unseen_cols:
        t.add_column(f"{escape(str(h))} (unseen)", justify="right")
    t.add_column("seen avg", justify="right")
    t.add_column("unseen avg", justify="right")
    if show_paper:
        for p in PAPER_TABLE_I:
            t.add_row(escape(f"paper: {p.method} ({p.variant})"), *(p.rates.get(h, "—") for h in cols), p.seen,
                      p.unseen)
        t.add_section()
        t.caption = escape(f"paper rows: {PAPER_TABLE_NAME}, quoted as printed (its averages over its "
                           "4 training / 2 unseen hands); — = not in that table")
    seen_avg_cols = [h for h in seen_cols if all(h in hs for *_, hs in rows)]
    unseen_avg_cols = [h for h in unseen_cols if all(h in hs for *_, hs in rows)]
    for name, policy, _, hs in rows:
        def avg(group: list[str]) -> str:
            return f"{sum(hs[h]['success_rate'] for h in group) / len(group):.3f}" if group else "—"

        label = f"{name} (scripted baseline)" if policy == "scripted" else f"{name} ({policy})"
        cells = [f"{hs[h]['success_rate']:.2f}" if h in hs else "—" for h in cols]
        t.add_row(escape(label), *cells, avg(seen_avg_cols), avg(unseen_avg_cols))
    labels = [len(f"{n} ({p})") + 20 for n, p, *_ in rows] + [60]
    wide = Console(file=console.file, emoji=False, width=max(console.width, max(labels) + 20 * (len(cols) + 2)))
    wide.print(t)
    if set(seen_avg_cols + unseen_avg_cols) != present:
        def named(group: list[str]) -> str:
            return ", ".join(group) if group else "none"

        wide.print(escape(f"note: our averages are over the hands every file has: seen {named(seen_avg_cols)}; "
                          f"unseen {named(unseen_avg_cols)}"), highlight=False)
    if show_paper:
        differ = [f"{h} (ours: {'train' if h in trained else 'unseen'}, paper: "
                  f"{'train' if h in PAPER_TRAINING_HANDS else 'unseen'})"
                  for h in cols if h in paper_names and (h in trained) != (h in PAPER_TRAINING_HANDS)]
        if differ:
            wide.print(escape("note: the split differs from the paper's for " + ", ".join(differ)), highlight=False)
    return 0


def render_object_table(files: list[Path], console) -> int:
    """Print success per object from `dgz eval --json` files (``console``: a rich Console), hardest object
    first: with one file, a column per hand and the mean over its hands; with several, each file's mean over
    its hands. The last row is the mean over objects. Returns the exit code (0); a file without per-object
    results is a one-line :class:`DgzError`."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    reports = []
    for f in files:
        rep = load_eval_report(Path(f))
        missing = [h for h, r in rep.hands.items() if not r.objects]
        if missing or not rep.hands:
            raise DgzError(f"{f}: no per-object results (field 'hands.{missing[0] if missing else '?'}.objects')",
                           "write the file with `dgz eval ... --json FILE`, which records every object")
        reports.append((Path(f).stem, rep))

    def means(rep: EvalReport) -> dict[str, float]:
        """object → mean over the hands that ran it."""
        per: dict[str, list[float]] = {}
        for r in rep.hands.values():
            for o, res in r.objects.items():
                per.setdefault(o, []).append(res.success_rate)
        return {o: sum(v) / len(v) for o, v in per.items()}

    all_means = [means(rep) for _, rep in reports]
    objects = sorted(set().union(*all_means), key=lambda o: (all_means[0].get(o, 2.0), o))
    t = Table(title="success rate per object (hardest first)")
    t.add_column("object", no_wrap=True)
    first = reports[0][1].hands  # sets the row order and, for a single file, the per-hand columns
    single = len(reports) == 1
    hands = sorted(first, key=_column_order) if single else []
    for h in hands:
        t.add_column(escape(h), justify="right")
    for name, _ in reports:
        t.add_column(escape(f"{name} mean" if not single else "mean over hands"), justify="right")

    def cell(x: float | None, digits: int = 2) -> str:
        return "—" if x is None else f"{x:.{digits}f}"

    for o in objects:
        row = [cell(first[h].objects[o].success_rate if o in first[h].objects else None) for h in hands]
        t.add_row(escape(o), *row, *(cell(m.get(o), 3) for m in all_means))
    t.add_section()
    avg = lambda xs: sum(xs) / len(xs) if xs else None  # noqa: E731
    t.add_row("mean over objects",
              *(cell(avg([r.success_rate for r in first[h].objects.values()])) for h in hands),
              *(cell(avg(list(m.values())), 3) for m in all_means))
    wide = Console(file=console.file, emoji=False, width=max(console.width, 40 + 10 * (len(hands) + len(reports))))
    wide.print(t)
    return 0
