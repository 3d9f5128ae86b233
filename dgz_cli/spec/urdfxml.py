"""Safe reading of a robot description (URDF or xacro) into sanitized XML that MuJoCo compiles.

Shared by onboarding and simulation; lives in ``spec`` so every layer can use it. XML is parsed
without DTDs or entity expansion; mesh paths (relative, absolute, ``file://``, ``package://``)
become absolute files; visuals are dropped (MuJoCo cannot decode .glb/.dae and physics does not
need them); any ``<mujoco>`` element the file carries is replaced by dgz's compiler settings.
"""

from __future__ import annotations

import hashlib
import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from dgz_cli.spec.errors import UrdfError


@dataclass(frozen=True)
class RobotXml:
    source: Path
    sha256: str
    root: etree._Element  # sanitized <robot>
    meshes: tuple[Path, ...]


def safe_parse(data: bytes, where: str) -> etree._Element:
    """Parse XML bytes with no DTD loading, no entity expansion and no network access."""
    if b"<!DOCTYPE" in data or b"<!ENTITY" in data:
        raise UrdfError(f"{where}: DOCTYPE/ENTITY declarations are not allowed in a robot description",
                        "remove the <!DOCTYPE ...> block; URDF never needs entities")
    parser = etree.XMLParser(
        resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False, remove_comments=True
    )
    try:
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as exc:
        raise UrdfError(f"{where}: malformed XML: {exc.msg} (line {exc.lineno})",
                        "fix the XML syntax; `xmllint --noout FILE` shows the exact spot") from None
    if root.getroottree().docinfo.internalDTD is not None:
        raise UrdfError(f"{where}: DOCTYPE/ENTITY declarations are not allowed in a robot description",
                        "remove the <!DOCTYPE ...> block; URDF never needs entities")
    return root


# --------------------------------------------------------------------------------------------------
# xacro: expanded in a child process, every expression checked before xacro evaluates it
# --------------------------------------------------------------------------------------------------
#
# xacro evaluates ``${...}`` with Python's eval() behind a thin name filter that is known to be
# escapable (``python.vars(...)``, ``xacro.load_yaml('/etc/passwd')``), and ``$(eval ...)`` runs with
# full builtins. dgz therefore (1) runs xacro in a child interpreter (``python -I``) with a memory,
# CPU and file-size limit, a minimal environment and a wall-clock timeout; (2) strips xacro's symbol
# table down to math; (3) checks the Python AST of every expression right before it is evaluated
# (after ``$(arg ...)`` substitution): only literals, arithmetic/boolean/comparison operators,
# conditional expressions, tuples/lists, names of declared properties and macro parameters, and calls
# of a few math functions are allowed; (4) allows only ``$(arg)``, ``$(find)``, ``$(dirname)`` and
# ``$(cwd)`` substitutions; ``$(find pkg)`` resolves inside the hand folder; (5) keeps every
# ``xacro:include`` inside the hand folder (the xacro's directory, or its parent when that directory is
# called ``urdf``), regular files of bounded size, without DOCTYPE/ENTITY declarations.

MAX_INPUT_BYTES = 64 * 1024 * 1024   # any URDF, xacro, include or mesh-free robot description
XACRO_TIMEOUT_S = 30.0
_XACRO_MEMORY = 2 * 1024 ** 3

_SAFE_MATH = ("pi", "e", "tau", "inf", "nan", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh",
              "cosh", "tanh", "sqrt", "exp", "log", "log10", "log2", "pow", "fabs", "floor", "ceil", "trunc",
              "radians", "degrees", "hypot", "copysign", "fmod", "isclose", "isfinite", "isnan", "isinf")
_SAFE_BUILTINS = ("abs", "min", "max", "round", "int", "float", "str", "bool", "len")
_SAFE_NODES = ("Expression", "BoolOp", "And", "Or", "BinOp", "Add", "Sub", "Mult", "Div", "FloorDiv", "Mod", "Pow",
               "UnaryOp", "UAdd", "USub", "Not", "Compare", "Eq", "NotEq", "Lt", "LtE", "Gt", "GtE", "In", "NotIn",
               "IfExp", "Constant", "Name", "Load", "Tuple", "List", "Call", "Attribute")
XACRO_HINT = ("dgz evaluates only arithmetic on xacro properties/args and math functions; expand a xacro you trust "
              "yourself (`xacro FILE > hand.urdf`) and onboard the URDF")


class XacroRefused(Exception):
    """A xacro expression, substitution or include that dgz will not evaluate (raised in the child)."""

    def __init__(self, what: str) -> None:
        super().__init__(what)
        self.what = what


def hand_folder(path: Path) -> Path:
    """The folder a robot description may read from: its directory, or the package above ``urdf/``."""
    d = Path(os.path.realpath(path)).parent
    return d.parent if d.name == "urdf" else d


def _short(text: str, n: int = 120) -> str:
    text = " ".join(str(text).split())
    return text if len(text) <= n else text[: n - 3] + "..."


def check_xacro_expression(expr: str, declared=lambda name: False) -> None:
    """Raise :class:`XacroRefused` unless ``expr`` is plain arithmetic on declared names and math.

    ``declared(name)`` says whether ``name`` is a property or macro parameter the file itself declared.
    An undeclared name that is not one of xacro's built-in symbols is left to fail as NameError.
    """
    import ast

    text = str(expr).strip()
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError:
        return  # xacro's own compile() reports it
    except (ValueError, RecursionError, MemoryError):
        raise XacroRefused(f"expression '{_short(text)}' (cannot be parsed safely)") from None
    nodes = list(ast.walk(tree))
    for node in nodes:  # first the constructs that are never allowed, so the message names them
        kind = type(node).__name__
        if kind not in _SAFE_NODES:
            label = {"Subscript": "subscript", "Lambda": "lambda", "ListComp": "comprehension",
                     "SetComp": "comprehension", "DictComp": "comprehension", "GeneratorExp": "comprehension",
                     "NamedExpr": "assignment", "Starred": "star-argument", "Dict": "dict", "Set": "set",
                     "JoinedStr": "f-string", "Await": "await", "Yield": "yield"}.get(kind, kind)
            raise XacroRefused(f"expression '{_short(text)}' (uses {label})")
        if isinstance(node, ast.Constant) and not isinstance(node.value, (int, float, str, bool, type(None))):
            raise XacroRefused(f"expression '{_short(text)}' (uses a {type(node.value).__name__} constant)")
        if isinstance(node, ast.Attribute) and not (isinstance(node.value, ast.Name) and node.value.id == "math"
                                                    and node.attr in _SAFE_MATH):
            raise XacroRefused(f"expression '{_short(text)}' (uses attribute access '.{node.attr}')")
    for node in nodes:
        if isinstance(node, ast.Call):
            f = node.func
            ok = ((isinstance(f, ast.Name) and (f.id in _SAFE_MATH or f.id in _SAFE_BUILTINS) and not declared(f.id))
                  or isinstance(f, ast.Attribute))  # math.<safe>, checked above
            if not ok or node.keywords:
                name = f.id if isinstance(f, ast.Name) else "a computed value"
                raise XacroRefused(f"expression '{_short(text)}' (calls {name!r}, not a math function)"
                                   if isinstance(f, ast.Name) else
                                   f"expression '{_short(text)}' (calls {name}, not a math function)")
        elif isinstance(node, ast.Name):
            if node.id.startswith("_"):
                raise XacroRefused(f"expression '{_short(text)}' (uses the name '{node.id}')")
            if node.id in _SAFE_MATH or node.id in _SAFE_BUILTINS or node.id == "math" or declared(node.id):
                continue
            if node.id in _XACRO_BUILTIN_NAMES:
                raise XacroRefused(f"expression '{_short(text)}' (uses xacro's built-in '{node.id}')")
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
            exp = node.right.operand if isinstance(node.right, ast.UnaryOp) else node.right
            if not (isinstance(exp, ast.Constant) and isinstance(exp.value, (int, float))
                    and abs(exp.value) <= 64):
                raise XacroRefused(f"expression '{_short(text)}' (** needs a constant exponent of at most 64; "
                                   "use pow() for floats)")
    if sum(isinstance(n, ast.BinOp) and isinstance(n.op, ast.Pow) for n in nodes) > 3:
        raise XacroRefused(f"expression '{_short(text)}' (more than 3 powers)")


_XACRO_BUILTIN_NAMES = frozenset((
    "python", "xacro", "load_yaml", "abs_filename", "dotify", "list", "dict", "map", "set", "tuple", "type", "vars",
    "range", "sorted", "zip", "filter", "enumerate", "getattr", "setattr", "eval", "exec", "open", "compile",
    "globals", "locals", "message", "warning", "error", "fatal", "print_location", "tokenize", "arg",
    "frozenset", "repr", "hash", "ord", "chr", "isinstance", "issubclass", "slice", "reversed", "sum", "any", "all",
    "divmod", "complex", "True", "False"))


def _read_bounded(path: Path, what: str = "robot description") -> bytes:
    """A regular file's bytes, refusing devices, FIFOs, directories and files over MAX_INPUT_BYTES."""
    import stat

    try:
        st = os.stat(path)
    except OSError:
        raise UrdfError(f"{path}: no such file", "check the path, or set --asset-root / DGZ_ASSET_ROOT") from None
    if not stat.S_ISREG(st.st_mode):
        raise UrdfError(f"{path}: not a regular file", f"give the path of a {what} file (not a device, FIFO or folder)")
    if st.st_size > MAX_INPUT_BYTES:
        raise UrdfError(f"{path}: {st.st_size} bytes, more than the {MAX_INPUT_BYTES // 2 ** 20} MB dgz reads",
                        f"is this really a {what}?")
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
    try:
        fd = os.open(path, flags)
    except OSError as exc:
        raise UrdfError(f"{path}: cannot be read ({exc.strerror})", "check the file's permissions") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # swapped between stat() and open()
            raise UrdfError(f"{path}: not a regular file", f"give the path of a {what} file")
        with os.fdopen(fd, "rb", closefd=False) as f:
            data = f.read(MAX_INPUT_BYTES + 1)
    finally:
        os.close(fd)
    if len(data) > MAX_INPUT_BYTES:
        raise UrdfError(f"{path}: more than the {MAX_INPUT_BYTES // 2 ** 20} MB dgz reads", f"is this really a {what}?")
    return data


def expand_xacro(path: Path, args: dict[str, str]) -> bytes:
    """Expand a xacro file in a sandboxed child process (see the notes above); UrdfError on any refusal."""
    import json
    import subprocess
    import sys

    path = Path(path)
    safe_parse(_read_bounded(path, "xacro"), str(path))  # refuse entity bombs before xacro's own parser sees it
    bad_args = [k for k, v in args.items() if not isinstance(k, str) or not isinstance(v, str)]
    if bad_args:
        raise UrdfError(f"{path}: xacro arg(s) {bad_args} are not text", "pass --xacro-arg KEY=VALUE")
    root = hand_folder(path)
    request = json.dumps({"path": os.path.realpath(path), "root": str(root), "args": dict(args)})
    package_parent = str(Path(__file__).resolve().parents[2])
    code = ("import sys; sys.path.insert(0, %r); from dgz_cli.spec.urdfxml import _xacro_child; _xacro_child()"
            % package_parent)
    env = {"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "LANG": "C.UTF-8", "LC_ALL": "C.UTF-8"}
    try:
        proc = subprocess.run([sys.executable, "-I", "-c", code], input=request.encode(), capture_output=True,
                              cwd=str(root), env=env, timeout=XACRO_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise UrdfError(f"{path}: xacro expansion did not finish within {XACRO_TIMEOUT_S:.0f} s",
                        "a macro probably recurses or expands without bound; fix the xacro") from None
    try:
        reply = json.loads(proc.stdout.decode("utf-8"))
    except (ValueError, UnicodeDecodeError):
        reply = None
    if not isinstance(reply, dict):
        why = f"signal {-proc.returncode}" if proc.returncode < 0 else f"exit code {proc.returncode}"
        raise UrdfError(f"{path}: xacro expansion failed: the sandboxed xacro process stopped ({why}) "
                        "without a result", "it probably ran out of its memory/CPU budget; fix the xacro")
    if reply.get("refused"):
        where = reply.get("file") or str(path)
        what = str(reply.get("what", ""))
        hint = ("keep every included file inside the hand folder " + str(root) if what.startswith("include")
                else "pass values with --xacro-arg KEY=VALUE; " + XACRO_HINT if what.startswith("substitution")
                else XACRO_HINT)
        raise UrdfError(f"{where}: refused xacro {_short(what, 240)}", hint)
    if not reply.get("ok"):
        raise UrdfError(f"{path}: xacro expansion failed: {_short(reply.get('message', ''), 300)}",
                        "check the macro/property named above and the --xacro-arg KEY=VALUE values")
    return str(reply["xml"]).encode("utf-8")


def _xacro_child() -> None:
    """Entry point of the sandboxed child: JSON request on stdin, JSON reply on stdout."""
    import json
    import sys

    try:
        import resource

        for lim, val in ((resource.RLIMIT_AS, _XACRO_MEMORY), (resource.RLIMIT_CPU, int(XACRO_TIMEOUT_S)),
                         (resource.RLIMIT_FSIZE, 0), (resource.RLIMIT_CORE, 0)):
            try:
                resource.setrlimit(lim, (val, val))
            except (ValueError, OSError):
                pass
    except ImportError:  # not POSIX: the parent's timeout still applies
        pass
    req = json.loads(sys.stdin.read())
    try:
        reply = {"ok": True, "xml": _xacro_expand_here(Path(req["path"]), dict(req["args"]), Path(req["root"]))}
    except XacroRefused as exc:
        reply = {"ok": False, "refused": True, "what": exc.what, "file": getattr(exc, "file", "")}
    except BaseException as exc:  # noqa: BLE001 - reported to the parent as one line
        refused = _find_refusal(exc)
        if refused is not None:
            reply = {"ok": False, "refused": True, "what": refused.what, "file": getattr(refused, "file", "")}
        else:
            msg = " ".join(str(exc).split()) or type(exc).__name__
            if isinstance(exc, RecursionError):
                msg = "macros or properties recurse without end"
            reply = {"ok": False, "message": msg[:2000]}
    sys.stdout.write(json.dumps(reply))
    sys.stdout.flush()


def _find_refusal(exc: BaseException | None, depth: int = 0):
    while exc is not None and depth < 50:
        if isinstance(exc, XacroRefused):
            return exc
        exc = getattr(exc, "exc", None) or exc.__cause__ or exc.__context__
        depth += 1
    return None


def _xacro_expand_here(path: Path, args: dict[str, str], root: Path) -> str:
    """Run xacro in this (child) process with the guards installed. Never call this in dgz itself."""
    import builtins
    import math

    import xacro

    root = Path(os.path.realpath(root))

    def current_file() -> str:
        stack = getattr(xacro, "filestack", None) or [str(path)]
        return str(stack[-1] or path)

    def refuse(what: str):
        exc = XacroRefused(what)
        exc.file = current_file()
        return exc

    # (2) a stripped symbol table: math only
    ns = xacro.NameSpace()
    ns.update({k: getattr(math, k) for k in _SAFE_MATH})
    table = {k: getattr(math, k) for k in _SAFE_MATH}
    table.update({k: getattr(builtins, k) for k in _SAFE_BUILTINS})
    table["math"] = ns
    xacro._global_symbols.clear()
    xacro._global_symbols.update(table)

    # (3) every expression checked right before evaluation
    original_eval = xacro.safe_eval

    def declared_in(symbols):
        def declared(name: str) -> bool:
            t = symbols
            while isinstance(t, xacro.Table):
                if dict.__contains__(t, name):
                    return True
                t = t.parent
            return False
        return declared

    def guarded_eval(expr, globals, locals=None):
        try:
            check_xacro_expression(expr, declared_in(globals))
        except XacroRefused as exc:
            raise refuse(exc.what) from None
        return original_eval(expr, globals, locals)

    xacro.safe_eval = guarded_eval

    # (4) substitution args
    original_ext = xacro.eval_extension

    def find_package(pkg: str) -> str:
        here = Path(current_file()).resolve().parent
        for d in (here, *here.parents):
            if d == root or root in d.parents:
                if d.name == pkg:
                    return str(d)
                if (d / pkg).is_dir() and _inside(d / pkg, root):
                    return str((d / pkg).resolve())
        return str(root)  # the hand folder is the package

    def guarded_extension(s):
        inner = str(s)[2:-1].strip()
        words = inner.split()
        cmd = words[0] if words else ""
        if cmd in ("arg", "dirname", "cwd"):
            return original_ext(s)
        if cmd == "find" and len(words) == 2:
            return find_package(words[1])
        raise refuse(f"substitution '$({_short(inner, 80)})' (only $(arg), $(find), $(dirname) and $(cwd) are allowed)")

    xacro.eval_extension = guarded_extension

    # (5) includes stay inside the hand folder
    original_includes = xacro.get_include_files

    def guarded_includes(filename_spec, symbols):
        for filename in original_includes(filename_spec, symbols):
            real = Path(os.path.realpath(filename))
            if not _inside(real, root):
                raise refuse(f"include '{_short(filename_spec, 80)}' (leaves the hand folder {root})")
            try:
                safe_parse(_read_bounded(real, "xacro include"), str(real))
            except UrdfError as exc:
                raise refuse(f"include '{_short(filename_spec, 80)}' ({exc.message})") from None
            yield str(real)

    xacro.get_include_files = guarded_includes

    doc = xacro.process_file(str(path), mappings=dict(args))
    xml = doc.toxml()
    if len(xml) > MAX_INPUT_BYTES:
        raise XacroRefused(f"output of {len(xml)} characters (more than {MAX_INPUT_BYTES // 2 ** 20} MB)")
    return xml


def _inside(p: Path, root: Path) -> bool:
    p = Path(os.path.realpath(p))
    return p == root or root in p.parents


def resolve_mesh(filename: str, urdf_dir: Path) -> Path:
    if filename.startswith("package://"):
        pkg, _, rest = filename[len("package://"):].partition("/")
        bases = [urdf_dir, *urdf_dir.parents]
        bases += [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
        for base in bases:
            for candidate in (base / rest if base.name == pkg else None, base / pkg / rest):
                if candidate is not None and candidate.is_file():
                    return candidate.resolve()
        return (urdf_dir / rest).resolve()
    if filename.startswith("file://"):
        filename = filename[len("file://"):]
    p = Path(filename)
    return (p if p.is_absolute() else urdf_dir / p).resolve()


def read_robot_xml(path: Path, xacro_args: dict[str, str] | None = None) -> RobotXml:
    """Read, expand (xacro), sanitize and resolve the meshes of a robot description."""
    path = Path(path)
    raw = _read_bounded(path)
    is_xacro = path.suffix == ".xacro" or path.name.endswith(".urdf.xacro")
    data = expand_xacro(path, xacro_args or {}) if is_xacro else raw
    root = safe_parse(data, str(path))
    if root.tag != "robot":
        raise UrdfError(f"{path}: root element is <{root.tag}>, expected <robot>", "is this really a URDF file?")
    for el in root.findall("mujoco"):
        root.remove(el)
    urdf_dir = path.parent.resolve()
    meshes: list[Path] = []
    missing: list[str] = []
    for link in root.findall("link"):
        for el in list(link.findall("visual")):
            link.remove(el)
        for el in link.findall("collision"):
            mesh = el.find("geometry/mesh")
            if mesh is None:
                continue
            fname = mesh.get("filename", "")
            resolved = resolve_mesh(fname, urdf_dir)
            if not resolved.is_file():
                missing.append(f"{fname} (link '{link.get('name')}')")
            mesh.set("filename", str(resolved))
            meshes.append(resolved)
    if missing:
        raise UrdfError(f"{path}: missing mesh file {missing[0]}"
                        + (f" and {len(missing) - 1} more" if len(missing) > 1 else ""),
                        "restore the mesh next to the URDF or fix the filename/package:// path")
    return RobotXml(path, hashlib.sha256(raw).hexdigest(), root, tuple(meshes))


def mujoco_xml(robot: RobotXml) -> str:
    """The sanitized URDF with dgz's MuJoCo compiler settings injected (what MuJoCo compiles).

    ``fusestatic="false"`` keeps fingertip/palm frames named in the URDF; ``balanceinertia``
    accepts vendor inertias that violate the triangle inequality; MuJoCo turns <mimic> into
    joint equality constraints.
    """
    root = etree.fromstring(etree.tostring(robot.root), etree.XMLParser(resolve_entities=False, no_network=True))
    mj = etree.Element("mujoco")
    etree.SubElement(mj, "compiler", meshdir=str(robot.source.parent.resolve()), strippath="false",
                     balanceinertia="true", discardvisual="true", fusestatic="false", angle="radian")
    root.insert(0, mj)
    return etree.tostring(root, encoding="unicode")


@contextmanager
def captured_mujoco_warnings():
    """Route MuJoCo's warnings (C-level ``mju_warning`` and the Python ``UserWarning`` that MjSpec
    compilation raises) into a list instead of stderr and ./MUJOCO_LOG.TXT."""
    import warnings as pywarnings

    import mujoco

    messages: list[str] = []
    pending: list[BaseException] = []

    def on_warning(msg) -> None:
        # Called from MuJoCo's C code: an exception (a Ctrl-C landing here) must not unwind through it (the
        # process aborts); keep it and raise it once the compile has returned to Python.
        try:
            messages.append(" ".join(str(msg).split()))
        except BaseException as exc:  # noqa: BLE001
            pending.append(exc)

    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(on_warning)
    try:
        with pywarnings.catch_warnings(record=True) as caught:
            pywarnings.simplefilter("always")
            yield messages
        messages.extend(" ".join(str(w.message).split()) for w in caught)
    finally:
        mujoco.set_mju_user_warning(previous)
    if pending:
        raise pending[0]
