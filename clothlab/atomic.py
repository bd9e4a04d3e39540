"""Atomic writes: a result is either complete or absent, never half-written (docs/design.md principle 6).

Files are written to a hidden temporary file in the destination's directory, flushed and fsync'ed, then
moved over the destination with :func:`os.replace` (atomic on POSIX and Windows within one file system).
A result directory is built in a hidden temporary directory next to its destination and renamed into place
only when the work inside the ``with`` block finished without an exception.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path

from clothlab.errors import ResultExistsError


def _umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync_directory(directory: Path) -> None:
    """Make a rename inside ``directory`` durable (best effort: not every platform can open directories)."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temp file in the same directory, fsync, os.replace).

    Missing parent directories are created.  The file gets the usual permissions (0666 minus the umask),
    not the 0600 of a temporary file.  On any error the destination is untouched and no temp file remains.
    """
    path = Path(path)
    parent = path.parent
    parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=parent, prefix=f".{path.name}.", suffix=".tmp")
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_directory(parent)
    return path


def atomic_write_text(path, text: str, *, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically; newlines are written as given (no platform translation)."""
    return atomic_write_bytes(path, text.encode(encoding))


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def _refuse_existing(dest: Path) -> None:
    raise ResultExistsError(
        f"{dest} already exists; use --force (force=True) to replace it", path=dest,
    )


@contextlib.contextmanager
def atomic_directory(dest, *, force: bool = False) -> Iterator[Path]:
    """Build a result directory atomically: yield a fresh hidden temporary directory next to ``dest``.

    On a clean exit the temporary directory replaces ``dest``; on an exception it is removed and ``dest``
    is untouched.  If ``dest`` exists and ``force`` is false, :class:`ResultExistsError` is raised before
    any work is done.  With ``force`` the old ``dest`` is removed only after the new one is complete and
    in place (it is first renamed aside, then deleted).
    """
    dest = Path(dest)
    if dest.exists() and not force:
        _refuse_existing(dest)
    parent = dest.parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=parent, prefix=f".{dest.name}.tmp-"))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())
        if dest.exists() or dest.is_symlink():
            if not force:  # appeared while we worked
                _refuse_existing(dest)
            aside = parent / f".{dest.name}.old-{uuid.uuid4().hex[:12]}"
            os.rename(dest, aside)
            try:
                os.rename(tmp, dest)
            except BaseException:
                os.rename(aside, dest)
                raise
            _remove(aside)
        else:
            os.rename(tmp, dest)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _fsync_directory(parent)
