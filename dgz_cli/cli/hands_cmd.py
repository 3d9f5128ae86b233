"""`dgz hands`: procedural hands with ground-truth labels, and onboarding's agreement with them."""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.markup import escape

from dgz_cli.spec.errors import DgzError

hands_app = typer.Typer(no_args_is_help=True, help="Procedural hands with labels known by construction, and "
                        "onboarding's agreement with them.")
_out = Console(emoji=False)

KINDS_HELP = "comma-separated kinds to draw from: hand (thumb + 2-4 fingers), claw, opposed (two revolute digits), jaw"


def _kinds(text: str) -> tuple[str, ...]:
    from dgz_cli.onboard.generate import KINDS

    kinds = tuple(k.strip() for k in text.split(",") if k.strip())
    bad = [k for k in kinds if k not in KINDS]
    if bad or not kinds:
        raise DgzError(f"--kinds: unknown kind '{bad[0] if bad else text}'", f"choose from {', '.join(KINDS)}")
    return kinds


def _out_dir(path: Path) -> Path:
    if path.exists() and not path.is_dir():
        raise DgzError(f"cannot write hands into {path}: it exists and is not a folder", "name a new or existing folder")
    return path


@hands_app.command("generate", help="Write random valid hand URDFs and the ground truth of every actuated joint "
                   "(finger class, node, primitive, sign), known from how each hand was built, never from running "
                   "the onboarding.")
def generate(
    seed: int = typer.Option(0, "--seed", help="random seed; the same seed and count give the same files"),
    count: int = typer.Option(10, "--count", min=1, max=100000, help="number of hands"),
    out_dir: Path = typer.Option(..., "-o", "--out", help="folder to write NAME.urdf + NAME.labels.json into"),
    kinds: str = typer.Option("hand,claw,opposed,jaw", "--kinds", help=KINDS_HELP),
    variants_of: Optional[str] = typer.Option(None, "--variants-of", help="instead of random hands, write variants "
                                              "of this hand (shipped name or spec file): every finger's links scaled "
                                              "×0.6–1.6, a fingertip joint or a finger removed at random, as GET-Zero's "
                                              "LEAP variants; labels from the base spec and the construction"),
    asset_root: Optional[str] = typer.Option(None, "--asset-root", help="folder holding hands/ and objects/ "
                                             "(default: $DGZ_ASSET_ROOT); for --variants-of"),
) -> None:
    if variants_of is not None:
        from dgz_cli.onboard.variants import write_variants
        from dgz_cli.spec.catalog import asset_root as resolve_root
        from dgz_cli.spec.catalog import resolve_spec, resolve_urdf
        from dgz_cli.spec.io import load_spec

        spec = load_spec(resolve_spec(variants_of))
        urdf = resolve_urdf(spec.provenance.urdf, resolve_root(asset_root))
        paths = write_variants(spec, urdf, _out_dir(out_dir), seed, count)
        _out.print(f"wrote {len(paths)} variants of {escape(spec.name)} (URDF + labels JSON) to {escape(str(out_dir))}")
        return
    from dgz_cli.onboard.generate import write_hands

    paths = write_hands(_out_dir(out_dir), seed, count, _kinds(kinds))
    _out.print(f"wrote {len(paths)} hands (URDF + labels JSON) to {escape(str(out_dir))}")


@hands_app.command("check", help="Onboard and lint every generated hand and compare it with its labels: agreement, "
                   "clean refusals, wrong specs that lint clean, lint refusals of correct specs. Exits 1 if any "
                   "spec is wrong or a correct one is refused.")
def check(
    folder: Optional[Path] = typer.Argument(None, help="folder written by `dgz hands generate` (default: generate "
                                            "--count hands of --seed into a temporary folder)"),
    seed: int = typer.Option(0, "--seed", help="seed of the generated hands when no folder is given"),
    count: int = typer.Option(200, "--count", min=1, max=100000, help="number of hands when no folder is given"),
    kinds: str = typer.Option("hand,claw,opposed,jaw", "--kinds", help=KINDS_HELP),
    as_json: bool = typer.Option(False, "--json", help="print only the JSON"),
) -> None:
    from dgz_cli.onboard.agreement import check_dir, summary
    from dgz_cli.onboard.generate import write_hands

    if folder is not None:
        if not folder.is_dir() or not any(folder.glob("*.labels.json")):
            raise DgzError(f"{folder}: no generated hands (NAME.labels.json) here",
                           "write some with `dgz hands generate -o DIR`, or omit the folder")
        result = summary(check_dir(folder))
    else:
        with tempfile.TemporaryDirectory(prefix="dgz-hands-") as tmp:
            write_hands(Path(tmp), seed, count, _kinds(kinds))
            result = summary(check_dir(Path(tmp)))
        result = dict(seed=seed, kinds=list(_kinds(kinds)), **result)
    bad = result["wrong"] + result["false_refusal"] + result["truth_refused"]
    if not as_json:
        _out.print(f"{result['hands']} hands: {result['agree']} agree, {result['refused']} refused cleanly, "
                   f"{result['wrong']} wrong but lint-clean, {result['false_refusal']} correct but refused by lint, "
                   f"{result['truth_refused']} ground truths refused by lint")
    sys.stdout.write(json.dumps(result, indent=2) + "\n")
    raise typer.Exit(1 if bad else 0)
