"""``history.jsonl`` of a training run, read back on ``--resume``: schema-checked (finite, bounded numbers)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Optional

from pydantic import BaseModel, ConfigDict, Field, RootModel, ValidationError

from dgz_cli.spec.errors import DgzError

MAX_HISTORY_BYTES = 256 * 1024 * 1024
_Number = Annotated[float, Field(allow_inf_nan=False, ge=-1e15, le=1e15)]
_Key = Annotated[str, Field(min_length=1, max_length=100, pattern=r"^[A-Za-z0-9_.\-]+$")]


class _Columns(RootModel[dict[_Key, Optional[_Number]]]):
    """The other columns: named finite numbers, or null where nothing was measured."""


class HistoryRow(BaseModel):
    """One iteration's row: its number plus named finite numbers (or null where nothing was measured)."""

    model_config = ConfigDict(extra="allow")

    iteration: Annotated[int, Field(ge=1, le=10**9, strict=True)]


def read_history(path: Path, upto: int) -> list[dict]:
    """The rows of ``path`` with ``iteration <= upto``, in order; any problem is one :class:`DgzError` naming the
    file, line and field."""
    from dgz_cli.spec.io import read_text_bounded

    hint = ("the run's history.jsonl is damaged: restore it from a backup, or delete it (the curve restarts; "
            "the weights are unaffected)")
    rows, last = [], 0
    for n, line in enumerate(read_text_bounded(Path(path), MAX_HISTORY_BYTES, DgzError).splitlines(), 1):
        if not line.strip():
            continue
        try:
            rec = json.loads(line)
        except (ValueError, RecursionError):
            raise DgzError(f"{path}:{n}: not a JSON line", hint) from None
        if not isinstance(rec, dict):
            raise DgzError(f"{path}:{n}: not a history row (a JSON object)", hint)
        try:
            HistoryRow.model_validate(rec)
            _Columns.model_validate({k: v for k, v in rec.items() if k != "iteration"})
        except ValidationError as exc:
            e = exc.errors()[0]
            loc = ".".join(str(p) for p in e["loc"] if p not in ("float", "none", "[key]")) or "(row)"
            raise DgzError(f"{path}:{n}: field '{loc}': {e['msg']}", hint) from None
        if rec["iteration"] <= last:
            raise DgzError(f"{path}:{n}: field 'iteration': {rec['iteration']} does not follow {last}", hint)
        last = rec["iteration"]
        if last <= upto:
            rows.append(rec)
    return rows
