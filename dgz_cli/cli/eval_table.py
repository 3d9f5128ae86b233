"""Schema of a `dgz eval --json` result file, as `dgz eval --table` reads it (finite, bounded fields)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from dgz_cli.spec.errors import DgzError

MAX_TABLE_BYTES = 16 * 1024 * 1024
_Name = Annotated[str, Field(min_length=1, max_length=200)]


class HandResult(BaseModel):
    model_config = ConfigDict(extra="allow")

    success_rate: Annotated[float, Field(allow_inf_nan=False, ge=0.0, le=1.0)]
    episodes: Annotated[int, Field(ge=0, le=10**9)] = 0


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
