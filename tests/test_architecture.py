"""The package's layering, read from the code with ``ast`` (every import, module-level or inside a function):
one-way data flow between layers (design.md), no import cycles between modules, typer/rich only in the CLI,
and no torch on the paths that do not need it."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

PACKAGE = REPO / "dgz_cli"
# layer → the layers it may import (itself included). The CLI is the composition root and may import all.
ALLOWED = {
    "spec": {"spec"},
    "onboard": {"spec", "onboard"},
    "sim": {"spec", "sim"},
    "hw": {"spec", "hw"},
    "policy": {"spec", "policy"},
    "viz": {"spec", "viz"},
    "rl": {"spec", "policy", "rl"},
    "runtime": {"spec", "hw", "sim", "policy", "rl", "runtime"},
    "bench": {"spec", "onboard", "sim", "policy", "rl", "bench"},
    "assets": {"spec", "assets"},
}
TERMINAL = {"typer", "rich", "click"}


def _module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path, module: str | None = None) -> set[str]:
    """Every module ``path`` (module name ``module``) imports, absolute names (``from x import y`` counts ``x``
    and ``x.y``)."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    me = (module or _module_name(path)).split(".")
    package = me if path.name == "__init__.py" else me[:-1]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)
    return out


MODULES = {_module_name(p): p for p in PACKAGE.rglob("*.py")}
GRAPH = {m: {i for i in _imports(p) if i in MODULES and i != m} for m, p in MODULES.items()}


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


@pytest.mark.parametrize("layer", sorted(ALLOWED))
def test_layers_import_one_way(layer):
    bad = []
    for module, path in MODULES.items():
        if _layer(module) != layer:
            continue
        for imp in _imports(path):
            parts = imp.split(".")
            if parts[0] == "dgz_cli" and len(parts) > 1 and parts[1] in ALLOWED.keys() | {"cli"}:
                if parts[1] not in ALLOWED[layer]:
                    bad.append(f"{module} imports {imp}")
            if parts[0] in TERMINAL:
                bad.append(f"{module} imports {imp} (only dgz_cli.cli talks to the terminal)")
    assert not bad, "\n".join(bad)


def test_the_checker_sees_lazy_and_relative_imports(tmp_path):
    """The checker itself: an import inside a function and a relative import are both found."""
    f = tmp_path / "x.py"
    f.write_text("def f():\n    from dgz_cli.rl import runner\n    from ..hw import driver\n    import rich.table\n")
    assert {"dgz_cli.rl.runner", "dgz_cli.hw.driver", "rich.table"} <= _imports(f, "dgz_cli.sim.x")


def test_no_import_cycles():
    """Tarjan's strongly connected components over the module graph (function-level imports included)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]
    sys.setrecursionlimit(10_000)

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            # a package __init__ and its own submodules importing each other is not a layering cycle
            real = [m for m in comp if not any(o != m and o.startswith(m + ".") for o in comp)]
            if len(comp) > 1 and len(real) > 1:
                cycles.append(sorted(comp))

    for v in GRAPH:
        if v not in index:
            visit(v)
    assert not cycles, cycles


def _modules_after(code: str) -> set[str]:
    probe = code + "\nimport sys\nprint(' '.join(sorted({m.split('.')[0] for m in sys.modules})))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, cwd=REPO, timeout=300)
    assert out.returncode == 0, out.stderr
    return set(out.stdout.split())


def test_help_imports_no_torch_or_mujoco():
    loaded = _modules_after("import sys\nfrom dgz_cli.cli.app import app\ntry:\n    app(['--help'], standalone_mode=False)\n"
                            "except SystemExit:\n    pass")
    assert not loaded & {"torch", "mujoco"}, sorted(loaded & {"torch", "mujoco"})
    loaded = _modules_after("from dgz_cli.cli.app import app\ntry:\n    app(['train', '--help'], standalone_mode=False)\n"
                            "except SystemExit:\n    pass")
    assert "torch" not in loaded


def test_deploy_scripted_never_imports_torch():
    code = ("from rich.console import Console\nfrom dgz_cli.cli import deploy_cmd\n"
            "assert deploy_cmd.run('sim', None, 'scripted', None, False, False, True, None, 'hold', None, "
            "Console(quiet=True)) == 0")
    assert "torch" not in _modules_after(code)
    # the probe can fail: a trained policy does bring torch in
    code = code.replace("'scripted'", "'dgz-cpu-warmstart'")
    assert "torch" in _modules_after(code)


def test_onboard_imports_only_what_onboarding_needs(tmp_path):
    """`dgz onboard` (issue 13's wall time from the shell): no torch, SciPy, trimesh, yourdfpy or matplotlib, and
    no training code on its path."""
    urdf = PACKAGE / "data" / "hands" / "dgz_tri.urdf"
    loaded = _modules_after(
        "import sys\nfrom dgz_cli.cli.app import app\ntry:\n"
        f"    app(['onboard', {str(urdf)!r}, '-o', {str(tmp_path / 'tri.yaml')!r}], standalone_mode=False)\n"
        "except SystemExit:\n    pass\n"
        f"assert __import__('pathlib').Path({str(tmp_path / 'tri.yaml')!r}).is_file()")
    heavy = {"torch", "scipy", "trimesh", "yourdfpy", "matplotlib", "tensorboard"}
    assert not loaded & heavy, sorted(loaded & heavy)
    assert {"mujoco", "typer", "rich"} <= loaded  # the probe ran the real command
