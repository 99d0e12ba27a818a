"""Every file the project writes or reads goes through here: early checks of an output path,
atomic writes (a temporary name in the same folder, then a rename), strict JSON, checked
inputs, a lock on a folder being written, and content hashes.

The guarantees (docs/DESIGN.md, "Guarantees"): an output is a regular file or nothing (a
symlink, device, FIFO or folder in its place is refused, never replaced); it appears whole or
not at all, a full disk or a denied write is one line naming the file; temporaries of a
killed process are removed by the next write of the same file; JSON holds no NaN or Infinity;
an input is a regular file of bounded size, JSON and TOML of bounded nesting.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import math
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sensorimotor.errors import InputError

DATABASE = "database (.npz)"  # what the messages call the inputs every command reads
RUN_FOLDER = "run folder"
MAX_TEXT_BYTES = 64 << 20  # a world file, a JSON file: far beyond any real one
MAX_NESTING = 64  # JSON and TOML: tables and lists within each other


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a device"),
        (stat.S_ISBLK, "a device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def check_writable(path: str | Path) -> Path:
    """Refuse early an output path whose folder is missing or cannot be written, or whose
    current occupant is not a regular file (a symlink, device, FIFO or folder is never
    replaced)."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    try:
        if path.is_symlink():
            raise InputError(f"{path}: is a symbolic link; give the path of a regular file")
        if path.exists():
            mode = path.stat().st_mode
            if stat.S_ISDIR(mode):
                raise InputError(f"{path}: is a folder, not a file path")
            if not stat.S_ISREG(mode):
                raise InputError(f"{path}: is {_kind(mode)}, not a regular file; give another path")
        if folder.exists() and not folder.is_dir():
            raise InputError(f"{path}: {folder} is a file, not a folder")
        if not folder.is_dir():
            raise InputError(f"{path}: folder {folder} does not exist")
    except OSError as err:  # a name too long, a loop of links
        raise InputError(f"{path}: cannot write there ({err.strerror})") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{path}: folder {folder} is not writable")
    return path


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # alive, someone else's
        return True
    return True


def _clean_stale(folder: Path, name: str) -> None:
    """Remove the temporaries of ``name`` left by processes that no longer run (a kill -9)."""
    pattern = re.compile(rf"\.{re.escape(name)}\.(\d+)\.[a-z0-9_]+\.tmp.*")
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            m = pattern.fullmatch(entry.name)
            if m and not _alive(int(m[1])):
                with contextlib.suppress(OSError):
                    os.unlink(entry.path)


@contextmanager
def atomic_path(path: Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``path``, renamed onto ``path`` if the block succeeds;
    an OSError in the block (a full disk, say) becomes an InputError naming ``path``."""
    path = check_writable(path)
    folder = path.parent if str(path.parent) else Path(".")
    _clean_stale(folder, path.name)
    try:
        fd, tmp = tempfile.mkstemp(
            prefix=f".{path.name}.{os.getpid()}.", suffix=f".tmp{suffix}", dir=folder
        )
    except OSError as err:
        raise InputError(f"{path}: cannot write in {folder} ({err.strerror})") from None
    os.close(fd)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
        try:
            yield Path(tmp)
        except OSError as err:
            why = err.strerror or err.__class__.__name__
            if err.errno == errno.ENOSPC:
                why = "no space left on the device"
            raise InputError(f"{path}: cannot write ({why})") from None
        check_writable(path)  # nothing took its place meanwhile
        try:
            os.replace(tmp, path)
        except OSError as err:
            raise InputError(f"{path}: cannot write ({err.strerror})") from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write a text file through a temporary file in the same folder, then rename."""
    path = Path(path)
    with atomic_path(path, path.suffix) as tmp:
        tmp.write_text(text)
    return path


def strict_json(obj, path: str | Path | None = None, indent: int | None = 2) -> str:
    """``json.dumps`` that refuses NaN and Infinity (they are not JSON) with an InputError
    naming the key where one is found (and the file it was for)."""

    def find(o, where: str) -> str | None:
        if isinstance(o, float) and not math.isfinite(o):
            return f"{where or 'the value'} is {o}"
        if isinstance(o, dict):
            keys = [(v, f"{where}.{k}" if where else str(k)) for k, v in o.items()]
        elif isinstance(o, list | tuple):
            keys = [(v, f"{where}[{i}]") for i, v in enumerate(o)]
        else:
            return None
        for v, key in keys:
            if (bad := find(v, key)) is not None:
                return bad
        return None

    try:
        return json.dumps(obj, indent=indent, allow_nan=False)
    except ValueError:
        bad = find(obj, "")
        raise InputError(
            f"{path or 'JSON output'}: refusing to write a number that is not one ({bad})"
        ) from None


def write_json_atomic(path: str | Path, obj) -> Path:
    """Strict JSON (``strict_json``) written atomically, ending with a newline."""
    return write_text_atomic(path, strict_json(obj, path) + "\n")


def _mode(path: Path, what: str) -> int:
    """``path``'s file mode (following links), or one line naming it where it cannot be had."""
    try:
        return path.stat().st_mode
    except (FileNotFoundError, NotADirectoryError):
        raise InputError(f"{path}: {what} not found") from None
    except OSError as err:
        raise InputError(f"{path}: cannot read {what} ({err.strerror})") from None


def check_input(path: str | Path, what: str, max_bytes: int | None = None) -> Path:
    """Refuse an input that is missing, a folder, not a regular file (a FIFO or device would
    hang or never end), or larger than ``max_bytes``; ``what`` names it in the message."""
    path = Path(path)
    mode = _mode(path, what)
    if stat.S_ISDIR(mode):
        raise InputError(f"{path}: is a folder, not a {what}")
    if not stat.S_ISREG(mode):
        raise InputError(f"{path}: is {_kind(mode)}, not a {what}")
    if max_bytes is not None and path.stat().st_size > max_bytes:
        raise InputError(f"{path}: {path.stat().st_size:,} bytes, too large for a {what}")
    return path


def check_input_dir(path: str | Path, what: str) -> Path:
    """Refuse an input folder that is missing or not a folder; ``what`` names it."""
    path = Path(path)
    mode = _mode(path, what)
    if not stat.S_ISDIR(mode):
        kind = "a file" if stat.S_ISREG(mode) else _kind(mode)
        raise InputError(f"{path}: is {kind}, not a {what}")
    return path


MAX_FOLDER_FILES = 10_000  # files in an input folder (a ROS 2 bag holds a handful)


def check_input_folder(
    folder: str | Path, what: str, max_bytes: int | None = None, max_files: int = MAX_FOLDER_FILES
) -> list[Path]:
    """An input that is a folder of files (a ROS 2 bag): the folder itself, then each file in
    it through ``check_input`` (a FIFO, a device, a link to one, a folder inside: refused
    before anything is opened); the files, sorted."""
    folder = Path(folder)
    mode = _mode(folder, what)
    if not stat.S_ISDIR(mode):
        raise InputError(f"{folder}: is {_kind(mode)}, not a {what} folder")
    try:
        with os.scandir(folder) as entries:
            files = []
            for entry in entries:
                files.append(Path(entry.path))
                if len(files) > max_files:
                    raise InputError(f"{folder}: more than {max_files:,} files for a {what}")
    except OSError as err:
        raise InputError(f"{folder}: cannot read {what} ({err.strerror})") from None
    for path in sorted(files):
        check_input(path, f"file of a {what}", max_bytes)
    return sorted(files)


def check_nesting(obj, source: str, limit: int = MAX_NESTING) -> None:
    """Refuse tables and lists nested deeper than ``limit`` (no real file is)."""
    stack = [(obj, 1)]
    while stack:
        o, depth = stack.pop()
        if isinstance(o, dict | list):
            if depth > limit:
                raise InputError(f"{source}: nested deeper than {limit} levels")
            stack.extend((v, depth + 1) for v in (o.values() if isinstance(o, dict) else o))


def read_json(path: str | Path, what: str):
    """A JSON file this package wrote: checked as an input, parsed, nesting bounded."""
    path = check_input(path, what, MAX_TEXT_BYTES)
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except RecursionError:
        raise InputError(f"{path}: nested too deeply to be a {what}") from None
    except (OSError, UnicodeDecodeError, ValueError) as err:
        raise InputError(f"{path}: not a readable {what} ({err.__class__.__name__})") from None
    check_nesting(obj, str(path))
    return obj


def read_json_if_any(path: str | Path, what: str):
    """A JSON file this package may have written earlier (a cache's key, a trial's result):
    None where there is none, or where it does not parse (it is made again); one that is not
    a regular file (a FIFO, a folder) or is too large is refused as any input is."""
    path = Path(path)
    try:
        mode = path.stat().st_mode
    except OSError:
        return None
    if not stat.S_ISREG(mode) or path.stat().st_size > MAX_TEXT_BYTES:
        check_input(path, what, MAX_TEXT_BYTES)  # raises, naming what it is
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
        check_nesting(obj, str(path))
    except (RecursionError, InputError, OSError, UnicodeDecodeError, ValueError):
        return None
    return obj


@contextmanager
def folder_lock(folder: Path, what: str) -> Iterator[None]:
    """Hold an exclusive lock on ``folder`` (its ``.lock`` file) while the block writes it:
    a second process that asks for it gets an InputError at once instead of writing the same
    files. The lock ends with the process, however it ends; a block that ends removes the
    lock file (a process killed inside it leaves an unheld one, which the next takes)."""
    lock = Path(folder) / ".lock"
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as err:
        raise InputError(f"{folder}: cannot lock the {what} ({err.strerror})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InputError(
                f"{folder}: another process is writing this {what}; wait for it or use another folder"
            ) from None
        try:
            yield
        finally:
            lock.unlink(missing_ok=True)  # held, so ours to remove: a finished folder has none
    finally:
        os.close(fd)


@contextmanager
def lock_folder(out: str | Path, what: str = "output folder") -> Iterator[None]:
    """Create ``out`` if needed and hold its lock (``folder_lock``) while a command writes it:
    the one lock of every folder a command writes, taken before its first byte; a folder made
    here and left empty by a refusal is removed again."""
    out = Path(out)
    if out.is_symlink() and not out.is_dir():
        raise InputError(f"{out}: is a symbolic link, not a folder")
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, not a folder")
    made = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{out}: cannot create the {what} ({err.strerror})") from None
    try:
        with folder_lock(out, what):
            yield
    except BaseException:
        with contextlib.suppress(OSError):
            if made and all(p.name == ".lock" for p in out.iterdir()):
                shutil.rmtree(out, ignore_errors=True)
        raise


def file_hash(path: str | Path) -> str:
    """SHA-256 of a file's bytes (what run folders record of their data)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
