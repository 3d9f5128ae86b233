"""`dgz lint`: schema + internal checks + agreement with the URDF, for one or more specs."""

from __future__ import annotations

import json

from rich.console import Console
from rich.markup import escape

from dgz_cli.spec.errors import DgzError


def run(specs: list[str], asset_root: str | None, as_json: bool, console: Console) -> int:
    from dgz_cli.onboard.verify import lint_file
    from dgz_cli.spec.catalog import resolve_spec
    from dgz_cli.spec.io import load_spec
    from dgz_cli.spec.lint import Finding

    report, failed = [], False
    for ref in specs:
        try:
            path = resolve_spec(ref)
            spec = load_spec(path)
            findings = lint_file(spec, path, asset_root)
        except DgzError as exc:
            path = ref
            findings = [Finding("error", "(file)", exc.message, exc.hint)]
        errors = [f for f in findings if f.level == "error"]
        failed |= bool(errors)
        report.append(dict(file=str(path), ok=not errors, findings=[f.as_dict() for f in findings]))
        if not as_json:
            status = "[green]ok[/]" if not errors else "[red]FAIL[/]"
            console.print(f"{status} {escape(str(path))}")
            for f in findings:
                colour = "red" if f.level == "error" else "yellow"
                console.print(f"  [{colour}]{f.level}[/] {escape(str(path))}: {escape(f.field)}: {escape(f.message)}"
                              f" [dim]— {escape(f.fix)}[/]", soft_wrap=True)
    if as_json:
        console.file.write(json.dumps(report, indent=2) + "\n")
    return 1 if failed else 0
