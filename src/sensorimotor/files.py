"""Files the project writes and reads: early checks of an output path, atomic writes (a
temporary name in the same folder, then a rename), and content hashes."""

from __future__ import annotations

import hashlib
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

from sensorimotor.errors import InputError


def check_writable(path: str | Path) -> Path:
    """Refuse early an output path whose folder is missing or cannot be written."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a file path")
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{path}: {folder} is a file, not a folder")
    if not folder.is_dir():
        raise InputError(f"{path}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"{path}: folder {folder} is not writable")
    return path


@contextmanager
def atomic_path(path: Path, suffix: str = ""):
    """Yield a temporary path beside ``path``, renamed onto ``path`` if the block succeeds."""
    path = check_writable(path)
    folder = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".tmp{suffix}", dir=folder)
    except OSError as err:
        raise InputError(f"{path}: cannot write in {folder} ({err.strerror})") from None
    os.close(fd)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual permissions
        yield Path(tmp)
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


def file_hash(path: str | Path) -> str:
    """SHA-256 of a file's bytes (what run folders record of their data)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
