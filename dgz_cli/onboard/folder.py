"""A folder of hand URDFs as hands to train or evaluate on (`dgz train --hands allegro,generated:DIR`,
`dgz eval --hand generated:DIR`).

Every ``NAME.urdf`` in the folder (written by `dgz hands generate`, random hands or variants) becomes a spec
``NAME.yaml`` beside it: onboarded and linted exactly as `dgz onboard` does, or reused when the spec already
there was onboarded from the same URDF bytes (its ``provenance.urdf_sha256``). The spec records its URDF
relative to the asset root when the folder lies inside it, else by absolute path, so its scene builds from
anywhere.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

from dgz_cli.spec.errors import DgzError, OnboardError

PREFIX = "generated:"


def _current(spec_path: Path, urdf: Path) -> bool:
    """The spec beside ``urdf`` was onboarded from these very bytes."""
    from dgz_cli.spec.io import load_spec

    if not spec_path.is_file():
        return False
    try:
        spec = load_spec(spec_path)
    except DgzError:
        return False
    return spec.provenance.urdf_sha256 == hashlib.sha256(urdf.read_bytes()).hexdigest()


def onboard_folder(folder: Path, asset_root: Path | None = None, reference: str | None = None) -> list[Path]:
    """The spec of every URDF in ``folder`` (sorted by name), onboarding those without a current one.

    ``reference`` is the option and value the user named the folder with, e.g. ``--hands generated:DIR`` (for
    messages). Raises one-line errors naming the folder (missing, no URDF) or the hand onboarding or lint
    refused."""
    from dgz_cli.onboard.pipeline import onboard
    from dgz_cli.onboard.verify import lint_file
    from dgz_cli.spec.io import write_spec

    ref = reference or f"--hands {PREFIX}{folder}"
    if not folder.is_dir():
        raise OnboardError(f"{ref}: {folder} is not a folder",
                           "write hands into it with `dgz hands generate -o DIR` (or --variants-of HAND)")
    urdfs = sorted(folder.glob("*.urdf"))
    if not urdfs:
        raise OnboardError(f"{ref}: {folder} holds no .urdf file",
                           "write hands into it with `dgz hands generate -o DIR` (or --variants-of HAND)")
    out = []
    for urdf in urdfs:
        spec_path = urdf.with_suffix(".yaml")
        if not _current(spec_path, urdf):
            name = urdf.stem.lower()
            try:
                result = onboard(urdf, name, asset_root)
            except DgzError as exc:
                raise OnboardError(f"{ref}: {urdf.name} was refused by onboarding ({exc.message})",
                                   f"remove {urdf.name} from {folder}, or fix it and retry") from None
            errors = [f for f in lint_file(result.spec, spec_path, str(asset_root) if asset_root else None,
                                           result.poser) if f.level == "error"]
            if errors:
                raise OnboardError(f"{ref}: {urdf.name} fails lint ({errors[0].message})",
                                   f"remove {urdf.name} from {folder}, or fix it and retry")
            write_spec(result.spec, spec_path, inputs=(urdf,))
        out.append(spec_path)
    return out


__all__ = ["onboard_folder", "PREFIX"]
