"""HandSpec ↔ YAML. Reading uses PyYAML's safe loader (libyaml's ``CSafeLoader`` when PyYAML was built with it,
else the pure-Python ``SafeLoader``: same documents, several times faster); writing is atomic (temp file + rename)."""

from __future__ import annotations

import json
import os
import signal
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path

import yaml
from pydantic import ValidationError

from dgz_cli.spec.errors import DgzError, SpecError
from dgz_cli.spec.models import HandSpec, Overrides

HEADER = "# HandSpec written by `dgz onboard` — edit overrides in an --overrides file, not here.\n"


_SafeLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_SafeDumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class _Dumper(_SafeDumper):
    """Safe representers; libyaml's emitter when available (the shipped specs test keeps its bytes identical to
    the pure-Python emitter's)."""


def _represent_list(dumper, data: list):
    flow = len(data) <= 27 and all(isinstance(x, (int, float)) for x in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_Dumper.add_representer(list, _represent_list)


def _first_error(exc: ValidationError) -> tuple[str, str]:
    err = exc.errors()[0]
    loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
    msg = err["msg"]
    if err["type"] == "extra_forbidden":
        return loc, f"unknown key '{loc}'"
    return loc, msg


def parse_spec(data: object, where: str) -> HandSpec:
    if not isinstance(data, dict):
        raise SpecError(f"{where}: not a HandSpec (top level must be a mapping)", "regenerate it with `dgz onboard`")
    version = data.get("schema_version")
    if version is not None and version != 1:
        raise SpecError(f"{where}: schema_version {version} is not supported by this dgz (expects 1)",
                        "re-onboard the hand with this dgz version")
    try:
        return HandSpec.model_validate(data)
    except ValidationError as exc:
        loc, msg = _first_error(exc)
        raise SpecError(f"{where}: field '{loc}': {msg}",
                        "fix that field or regenerate the spec with `dgz onboard`") from None


MAX_YAML_BYTES = 64 * 1024 * 1024


def read_text_bounded(path: Path, limit: int = MAX_YAML_BYTES, error=SpecError) -> str:
    """A regular file's UTF-8 text; devices, FIFOs, folders and files over ``limit`` bytes are refused
    (``error`` is the DgzError class raised, naming the file)."""
    import stat

    path = Path(path)
    try:
        st = os.stat(path)
    except OSError:
        raise error(f"{path}: no such file", "check the path (`dgz show --list` lists shipped hands)") from None
    if not stat.S_ISREG(st.st_mode):
        raise error(f"{path}: not a regular file", "give the path of a file (not a device, FIFO or folder)")
    if st.st_size > limit:
        raise error(f"{path}: {st.st_size} bytes, more than the {limit >> 20} MB dgz reads", "is this the right file?")
    try:
        with open(path, "rb") as fh:
            data = fh.read(limit + 1)
    except OSError as exc:
        raise error(f"{path}: cannot be read ({exc.strerror})", "check the file's permissions") from None
    if len(data) > limit:
        raise error(f"{path}: more than the {limit >> 20} MB dgz reads", "is this the right file?")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise error(f"{path}: not a UTF-8 text file", "is this really a YAML file?") from None


def read_yaml(path: Path) -> object:
    path = Path(path)
    text = read_text_bounded(path)
    try:
        return yaml.load(text, Loader=_SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f" (line {mark.line + 1})" if mark is not None else ""
        raise SpecError(f"{path}: malformed YAML{at}: {getattr(exc, 'problem', exc)}", "fix the YAML syntax") from None
    except UnicodeDecodeError:
        raise SpecError(f"{path}: not a UTF-8 text file", "is this really a YAML file?") from None


def load_spec(path: Path) -> HandSpec:
    return parse_spec(read_yaml(path), str(path))


def load_overrides(path: Path) -> Overrides:
    data = read_yaml(path)
    if data is None:
        data = {}
    try:
        return Overrides.model_validate(data)
    except ValidationError as exc:
        loc, msg = _first_error(exc)
        raise SpecError(f"{path}: field '{loc}': {msg}", "see docs/handspec.md for the overrides format") from None


def spec_to_yaml(spec: HandSpec) -> str:
    data = json.loads(spec.model_dump_json())
    return HEADER + yaml.dump(data, Dumper=_Dumper, sort_keys=False, width=120, allow_unicode=True)


def check_output(path: Path, option: str = "output") -> None:
    """Refuse an output target up front (before a long run), with the one line :func:`atomic_write_bytes`
    would give at the end: a target (through symlinks) that exists and is not a regular file, a name too
    long, or a folder that cannot be created or written to (nearest existing ancestor not a folder, or not
    writable — a read-only mount included)."""
    import stat

    path = Path(path)
    hint = f"choose another {option} path"
    target = Path(os.path.realpath(path))
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise DgzError(f"cannot write {path}: {exc.strerror or exc}", hint) from None
    if st is not None and not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file (a device, FIFO or socket)"
        raise DgzError(f"cannot write {path}: it exists and is {kind}", f"name a new or regular file as {option}")
    folder = target.parent
    while not os.path.lexists(folder) and folder != folder.parent:
        folder = folder.parent
    if not os.path.isdir(folder):
        raise DgzError(f"cannot write {path}: {folder} is not a folder", hint)
    try:
        name_max = os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    if len(target.name.encode("utf-8", "surrogateescape")) > name_max:
        raise DgzError(f"cannot write {path}: file name too long (more than {name_max} bytes)", hint)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise DgzError(f"cannot write {path}: folder {folder} is not writable", hint)


@contextmanager
def _stop_signals_deferred():
    """Hold Ctrl-C, SIGTERM and SIGHUP until the block is done, then deliver them to the handlers that were in place:
    a stop that lands inside a write (even between the temporary file's creation and its name reaching us) must
    not leave a temporary file behind. Only the main thread receives Python signals; elsewhere this does nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    names = ("SIGINT", "SIGTERM", "SIGHUP")
    stops = [getattr(signal, n) for n in names if hasattr(signal, n)]
    previous = {s: signal.getsignal(s) for s in stops}
    pending: list[int] = []
    for s in stops:
        signal.signal(s, lambda sig, _frame: pending.append(sig))
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
        for sig in dict.fromkeys(pending):
            signal.raise_signal(sig)


def atomic_write_bytes(path: Path, data: bytes, *, inputs=()) -> None:
    """Write ``data`` to ``path`` via a temporary file in the same directory and a rename, so a reader
    (or a crash) never sees a half-written file; the result gets the usual umask-derived mode.

    A symlink is written through (its target is replaced, the link stays). A target that exists and is
    not a regular file (a device such as /dev/full, a FIFO, a folder) is refused, and so is a target that
    is one of ``inputs`` (``-o`` equal to the file being read). Any OSError (read-only mount, ENOSPC, a
    name too long, a missing permission) becomes a one-line :class:`DgzError` naming the path; nothing
    is left behind.
    """
    import stat

    path = Path(path)
    target = Path(os.path.realpath(path))  # through symlinks (a dangling one: its target)
    try:
        st = os.stat(target)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise DgzError(f"cannot write {path}: {exc.strerror}", "choose another output path") from None
    if st is not None and not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file (a device, FIFO or socket)"
        raise DgzError(f"cannot write {path}: it exists and is {kind}",
                       "name a new or regular file as the output")
    for src in inputs:
        try:
            same = st is not None and os.path.samefile(src, target)
        except OSError:
            same = False
        if same:
            raise DgzError(f"cannot write {path}: it is the input file {src}",
                           "choose an output path different from the input")
    with _stop_signals_deferred():
        _write_and_rename(path, target, data)


def _write_and_rename(path: Path, target: Path, data: bytes) -> None:
    tmp = None
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name[:200]}.", suffix=".tmp", dir=target.parent)
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, target)
        tmp = None
    except OSError as exc:
        raise DgzError(f"cannot write {path}: {exc.strerror or exc}",
                       "check that the folder exists and is writable and that the disk has space") from None
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)


def atomic_write(path: Path, text: str, inputs=()) -> None:
    atomic_write_bytes(path, text.encode("utf-8"), inputs=inputs)


def write_spec(spec: HandSpec, path: Path, inputs=()) -> None:
    """Write ``spec`` atomically; never over its own source URDF (when recorded as an absolute path) or
    any of ``inputs``."""
    src = spec.provenance.urdf
    own = (src,) if os.path.isabs(src) else ()
    atomic_write_bytes(path, spec_to_yaml(spec).encode("utf-8"), inputs=(*own, *inputs))
