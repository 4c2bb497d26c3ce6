"""File I/O at the edges: atomic outputs and bounded, checked inputs.

Outputs are written to a temporary file in the target folder, then renamed onto the target.
A failure at any point removes the temporary file, so no half-written output is ever left
behind, and an existing output is only replaced by a complete new one.  Outputs are regular
files or absent: a target that exists as anything else (a folder, a device node, a FIFO) is
refused rather than replaced.  Whether an existing regular file may be replaced is checked
again at the rename (:func:`output_policy`), so a file that appeared while the work ran is not
silently replaced.

Inputs are opened only when they are regular files of a bounded size (a device node or a FIFO
would be read forever), decoded as UTF-8 with the offending byte named, and JSON is refused
above a nesting depth (Python's parser recurses once per level).
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from wholearm_tools import _interrupt
from wholearm_tools.errors import InputError, OutputError, WholearmError

#: largest text input read whole into memory (map.json, contacts.csv, URDF, scenario YAML)
MAX_TEXT_BYTES = 256 * 1024 * 1024
#: deepest JSON nesting accepted (map.json nests 4 levels; logs' JSON messages a few more)
MAX_JSON_DEPTH = 64

_REPLACE_EXISTING: contextvars.ContextVar[bool] = contextvars.ContextVar(
    "wholearm_replace_existing", default=True)


@contextlib.contextmanager
def output_policy(*, overwrite: bool) -> Iterator[None]:
    """Within the block, atomic writes replace an existing output only if ``overwrite``.

    The check is made at the rename itself (a hard link, which fails on an existing name), so
    an output that appeared after a command's up-front check is refused, not replaced.  The
    library default (outside any block) is to replace.
    """
    token = _REPLACE_EXISTING.set(bool(overwrite))
    try:
        yield
    finally:
        _REPLACE_EXISTING.reset(token)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def check_output_target(target: str | os.PathLike[str]) -> None:
    """OutputError unless ``target`` is absent or a regular file (symlinks followed)."""
    target = Path(target)
    try:
        mode = os.stat(target).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise OutputError(f"{target}: cannot check output ({exc.strerror})") from None
    if stat.S_ISDIR(mode):
        raise OutputError(f"{target}: is a folder, not an output file")
    if not stat.S_ISREG(mode):
        raise OutputError(f"{target}: exists and is not a regular file (a device, FIFO or "
                          "socket); refusing to replace it")


def _write_error(target: Path, exc: BaseException) -> OutputError:
    """One line naming the output for an OS-level failure while writing it."""
    cause: BaseException | None = exc
    while cause is not None and not isinstance(cause, OSError):
        cause = cause.__context__  # e.g. zlib.error raised while a writer cleans up after ENOSPC
    reason = (cause.strerror or str(cause)) if isinstance(cause, OSError) else str(exc)
    return OutputError(f"{target}: cannot write output ({reason or type(exc).__name__})")


def _is_write_failure(exc: BaseException) -> bool:
    """An OS error (or an error raised while handling one) that is not already ours."""
    if isinstance(exc, WholearmError):
        return False
    cause: BaseException | None = exc
    while cause is not None:
        if isinstance(cause, OSError) and not isinstance(cause, WholearmError):
            return True
        cause = cause.__context__
    return False


def _commit(tmp: Path, target: Path, replace: bool) -> None:
    """Rename ``tmp`` onto ``target``; without ``replace``, fail if ``target`` exists.  Nothing
    is put in place once Ctrl-C was pressed (:mod:`wholearm_tools._interrupt`)."""
    _interrupt.check()
    check_output_target(target)
    if replace:
        os.replace(tmp, target)
        return
    try:
        os.link(tmp, target)
    except FileExistsError:
        raise OutputError(f"{target}: already exists (use --overwrite to replace it)") from None
    except OSError as exc:
        if exc.errno not in (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV,
                             errno.EMLINK):
            raise
        # a file system without hard links: check, then rename (a small window remains)
        if target.exists():
            raise OutputError(f"{target}: already exists (use --overwrite to replace it)") \
                from None
        os.replace(tmp, target)
        return


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str], suffix: str = ".tmp", *,
                overwrite: bool | None = None) -> Iterator[Path]:
    """Yield a temporary path next to ``target``; rename it onto ``target`` on success, remove
    it on failure.

    The temporary file has ``target``'s own name (plus ``suffix`` unless the name already ends
    with it) inside a hidden temporary folder beside ``target``: writers that take a file name
    (open3d, pyvista, matplotlib) dispatch on its extension, and those that record the name in
    the file (an OBJ's object name) record the output's name, not a random one.

    ``overwrite`` None follows :func:`output_policy` (replace, outside any policy block).
    OS errors while writing (a full disk, a lost mount) become one :class:`OutputError` naming
    ``target``.
    """
    target = Path(target)
    replace = _REPLACE_EXISTING.get() if overwrite is None else bool(overwrite)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise OutputError(f"{target}: output folder {folder} does not exist")
    check_output_target(target)
    try:
        scratch = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=folder))
    except OSError as exc:
        raise OutputError(f"{target}: cannot write output ({exc.strerror})") from None
    tmp = scratch / (target.name if target.name.endswith(suffix) else target.name + suffix)
    try:
        tmp.touch()
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())  # the usual mode for outputs
        _commit(tmp, target, replace)
    except BaseException as exc:
        if isinstance(exc, Exception) and _is_write_failure(exc):
            raise _write_error(target, exc) from None
        raise
    finally:
        _remove_scratch(scratch)


def _remove_scratch(folder: Path) -> None:
    """Remove a scratch folder and what a writer left in it (a writer may add sidecar files);
    errors are ignored: the output itself is already in place or the error is being raised."""
    with contextlib.suppress(OSError):
        for entry in folder.iterdir():
            with contextlib.suppress(OSError):
                if entry.is_dir() and not entry.is_symlink():
                    _remove_scratch(entry)
                else:
                    entry.unlink()
        folder.rmdir()


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike[str], mode: str = "wb") -> Iterator[IO]:
    """Open a temporary file next to ``path`` for writing; on success rename it onto ``path``."""
    with atomic_path(path) as tmp, open(tmp, mode) as handle:
        yield handle


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    write_bytes_atomic(path, text.encode("utf-8"))


# ----------------------------------------------------------------------------------- inputs


def check_input_file(path: str | os.PathLike[str], what: str, *,
                     max_bytes: int | None = None,
                     error: type[WholearmError] = InputError) -> int:
    """Size in bytes of ``path``, after checking it is a regular file (symlinks followed) of
    at most ``max_bytes``; otherwise ``error`` naming the file and what was expected."""
    path = Path(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise error(f"{path}: cannot read {what} (no such file)") from None
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror})") from None
    if stat.S_ISDIR(info.st_mode):
        raise error(f"{path}: is a folder, not a {what}")
    if not stat.S_ISREG(info.st_mode):
        raise error(f"{path}: not a regular file (a device, FIFO or socket), not a {what}")
    if max_bytes is not None and info.st_size > max_bytes:
        raise error(f"{path}: {_size(info.st_size)} is too large for a {what} (at most "
                    f"{_size(max_bytes)})")
    return int(info.st_size)


def _size(n: int) -> str:
    """A byte count as people read it (bytes, KiB, MiB or GiB)."""
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} bytes"


def read_text_input(path: str | os.PathLike[str], what: str, *,
                    max_bytes: int = MAX_TEXT_BYTES,
                    error: type[WholearmError] = InputError) -> str:
    """The UTF-8 text of a bounded regular file; errors name the file (and the first byte
    that is not UTF-8)."""
    path = Path(path)
    check_input_file(path, what, max_bytes=max_bytes, error=error)
    try:
        with open(path, "rb") as handle:
            data = handle.read(max_bytes + 1)
    except OSError as exc:
        raise error(f"{path}: cannot read {what} ({exc.strerror})") from None
    if len(data) > max_bytes:  # grew since the check
        raise error(f"{path}: too large for a {what} (at most {_size(max_bytes)})")
    return decode_utf8(data, f"{path}", what, error=error)


def decode_utf8(data: bytes, source: str, what: str, *,
                error: type[WholearmError] = InputError) -> str:
    """``data`` as UTF-8 text (a leading byte-order mark dropped); ``error`` naming ``source``
    and the offset of the first invalid byte otherwise."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise error(f"{source}: {what} is not UTF-8 text (byte 0x{data[exc.start]:02x} at "
                    f"offset {exc.start})") from None


def json_depth(value: Any, limit: int | None = None) -> int:
    """Deepest nesting of lists and dicts in a parsed JSON ``value`` (a scalar is 0), walked
    without recursion; stops counting once ``limit`` is exceeded."""
    depth = 0
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, level = stack.pop()
        if isinstance(item, dict):
            item = list(item.values())
        elif not isinstance(item, list):
            continue
        depth = max(depth, level)
        if limit is not None and depth > limit:
            return depth
        stack.extend((child, level + 1) for child in item
                     if isinstance(child, (list, dict)))
    return depth


def load_json(text: str | bytes, source: str, what: str = "JSON", *,
              max_depth: int = MAX_JSON_DEPTH,
              error: type[WholearmError] = InputError) -> Any:
    """Parse JSON ``text`` and bound its nesting depth; errors name ``source``.

    Python's parser recurses once per level and stops with RecursionError near a thousand
    levels; anything deeper than ``max_depth`` is refused the same way, so later recursive
    walks over the value are safe."""
    import json

    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{source}: malformed {what} ({exc.msg} at line {exc.lineno})") from None
    except RecursionError:
        raise error(f"{source}: {what} nested too deeply (at most {max_depth} levels)") \
            from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise error(f"{source}: malformed {what} ({type(exc).__name__})") from None
    if json_depth(value, max_depth) > max_depth:
        raise error(f"{source}: {what} nested too deeply (at most {max_depth} levels)")
    return value
