"""Atomic writes: a result is either complete or absent, never half-written (docs/design.md principle 6).

Files are written to a hidden temporary file in the destination's directory, flushed and fsync'ed, then
moved over the destination with :func:`os.replace` (atomic on POSIX and Windows within one file system).
A result directory is built in a hidden temporary directory next to its destination and swapped into place
only when the work inside the ``with`` block finished without an exception, under a per-result lock
(``.<name>.lock``): a second writer of the same result is refused at once, an interrupted swap is completed or
rolled back by the next writer, and stale temporaries are removed (:func:`recover`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import sys
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path

from clothlab.errors import OutputError, ResultBusyError, ResultExistsError


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
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def _refuse_existing(dest: Path) -> None:
    raise ResultExistsError(
        f"{dest} already exists; use --force (force=True) to replace it", path=dest,
    )


# ---------------------------------------------------------------------------------------------------------
# Interrupts: a Ctrl-C that a C callback swallowed (numba / llvmlite compilation prints "Exception ignored")
# still stops the command before a result is committed.

_INTERRUPTED = False
_REDELIVER = False
_ACTIVE = False  # inside an interrupts_recorded block


def _on_sigint(signum, frame):
    global _INTERRUPTED, _REDELIVER
    if _REDELIVER:  # the KeyboardInterrupt of a Ctrl-C was swallowed by a callback: raise it again here
        _REDELIVER = False
        raise KeyboardInterrupt
    if _INTERRUPTED:  # a second Ctrl-C while the first one unwinds: already stopping
        return
    _INTERRUPTED = True
    raise KeyboardInterrupt


def _swallowed(previous_hook):
    """A ``sys.unraisablehook`` that, for a KeyboardInterrupt raised where Python could only print "Exception
    ignored" (a weakref or C callback, e.g. during numba compilation), prints nothing and delivers the
    interrupt again to the main thread; anything else goes to ``previous_hook``."""
    def hook(unraisable):
        global _REDELIVER
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            import _thread
            import signal
            import threading

            _REDELIVER = True  # from another thread, so the handler runs after this callback has returned
            threading.Timer(0.01, _thread.interrupt_main, (signal.SIGINT,)).start()
            return
        previous_hook(unraisable)
    return hook


def _quiet_interrupt(previous_hook):
    """A ``sys.excepthook`` that prints nothing for a KeyboardInterrupt (compiled extensions print the
    traceback of an exception they cannot propagate through it, then report it as unraisable)."""
    def hook(exc_type, exc_value, tb):
        if issubclass(exc_type, KeyboardInterrupt):
            return
        previous_hook(exc_type, exc_value, tb)
    return hook


@contextlib.contextmanager
def interrupts_recorded() -> Iterator[None]:
    """Install a SIGINT handler that records the interrupt before raising KeyboardInterrupt, for the
    ``with`` block (main thread only; elsewhere a no-op).  :func:`atomic_directory` refuses to commit a
    result once an interrupt was recorded, even if the KeyboardInterrupt was swallowed on the way.  Further
    Ctrl-C are ignored once one was recorded (also after the block: the process is stopping), so a second
    Ctrl-C while the first unwinds cannot turn into a traceback."""
    import signal
    import threading

    global _INTERRUPTED, _REDELIVER, _ACTIVE
    _REDELIVER = False
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, _on_sigint)
    previous_hook, previous_excepthook = sys.unraisablehook, sys.excepthook
    sys.unraisablehook = _swallowed(previous_hook)
    sys.excepthook = _quiet_interrupt(previous_excepthook)
    _INTERRUPTED, _ACTIVE = False, True
    try:
        yield
    finally:
        _ACTIVE = False
        sys.unraisablehook, sys.excepthook = previous_hook, previous_excepthook
        if not _INTERRUPTED and signal.getsignal(signal.SIGINT) is _on_sigint:
            signal.signal(signal.SIGINT, previous)


def was_interrupted() -> bool:
    """True inside an :func:`interrupts_recorded` block once a Ctrl-C was recorded in it."""
    return _ACTIVE and _INTERRUPTED


def check_interrupted() -> None:
    """KeyboardInterrupt if a Ctrl-C was recorded in the current :func:`interrupts_recorded` block (and
    swallowed since)."""
    if was_interrupted():
        raise KeyboardInterrupt


# ---------------------------------------------------------------------------------------------------------
# Fault injection (tests only): called at each step of the swap; a test replaces it to SIGKILL the process.

def _step(name: str) -> None:
    """No-op hook between the steps of :func:`atomic_directory` ('built', 'exchanged', 'aside', 'renamed')."""


# ---------------------------------------------------------------------------------------------------------
# Exchanging two directories in one system call (Linux renameat2 RENAME_EXCHANGE), where available.

_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap the names ``a`` and ``b`` (both must exist); False when the platform or file system
    cannot, so the caller falls back to a rename aside."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.EPERM):
        return False
    raise OSError(err, os.strerror(err), str(b))


# ---------------------------------------------------------------------------------------------------------
# Per-result lock, recovery of interrupted swaps, and output checks done before any work

HIDDEN_SUFFIX = "posterior-checkpoint.npz"
"""The longest suffix of a hidden sibling ``.<name>.<suffix>`` of a result (the posterior checkpoint)."""
_HELD: dict[Path, int] = {}  # lock path -> depth (a process may re-enter its own lock)


def lock_path(dest) -> Path:
    """The hidden lock file of a result directory: ``.<name>.lock`` next to it."""
    dest = Path(dest)
    return dest.parent / f".{dest.name}.lock"


def _hidden_names(dest: Path, kind: str) -> list[Path]:
    try:
        return sorted(dest.parent.glob(f".{glob_escape(dest.name)}.{kind}-*"))
    except OSError:
        return []


def glob_escape(name: str) -> str:
    """``name`` with glob metacharacters escaped."""
    return "".join(f"[{c}]" if c in "*?[" else c for c in name)


def recover(dest) -> list[str]:
    """Complete or roll back an interrupted replacement of ``dest`` and remove stale temporaries.

    Call with the lock of ``dest`` held (:func:`result_lock`).  If ``dest`` is missing but a
    ``.<name>.old-*`` directory exists (a kill between the two renames of the fallback swap), the newest one
    is renamed back: the previous complete result is reachable again.  With ``dest`` present, ``.old-*``
    leftovers are removed; ``.tmp-*`` directories (a killed build, or the old result after an exchange)
    are always removed.  Returns one sentence per action, for the log.
    """
    dest = Path(dest)
    actions = []
    olds = sorted(_hidden_names(dest, "old"), key=lambda p: p.stat().st_mtime if p.exists() else 0.0)
    if olds and not (dest.exists() or dest.is_symlink()):
        os.rename(olds[-1], dest)
        actions.append(f"restored the previous result {dest} from {olds[-1].name} (an earlier replacement "
                       "was interrupted)")
        olds = olds[:-1]
    for path in olds + _hidden_names(dest, "tmp"):
        _remove(path)
        actions.append(f"removed {path.name}, left by an interrupted run")
    if actions:
        _fsync_directory(dest.parent)
    return actions


def _nearest_existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def check_output_dir(dest) -> None:
    """OutputError naming the path unless ``dest``'s parent can hold it: no NUL byte, a name the file system
    accepts (with room for the hidden ``.<name>.tmp-*`` / ``.posterior-checkpoint.npz`` siblings), and a
    parent that is (or can be created as) a writable directory."""
    text = str(dest)
    if "\x00" in text:
        raise OutputError("output path holds a NUL byte", path=repr(text))
    dest = Path(dest)
    try:
        base = _nearest_existing(dest.parent)
        if not base.is_dir():
            raise OutputError(f"{base} is a file, not a directory: cannot create {dest} inside it", path=base)
        try:
            name_max = os.pathconf(base, "PC_NAME_MAX")
        except (OSError, ValueError):
            name_max = 255
        size = len(os.fsencode(dest.name))
        allowed = name_max - len(os.fsencode(f"..{HIDDEN_SUFFIX}"))
        if size > allowed:
            raise OutputError(f"the name {dest.name[:40]!r}... is {size} bytes long; with clothlab's hidden "
                              f"siblings it must stay within {allowed} bytes on this file system", path=dest.parent)
        dest.parent.mkdir(parents=True, exist_ok=True)
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"cannot create the output directory: {exc.strerror or exc}",
                          path=exc.filename or dest.parent) from None
    if not os.access(dest.parent, os.W_OK | os.X_OK):
        raise OutputError("the output directory is not writable", path=dest.parent)


@contextlib.contextmanager
def result_lock(dest) -> Iterator[Path]:
    """Hold the lock of result directory ``dest`` (``.<name>.lock``, flock) for the ``with`` block.

    A second process asking for the same lock is refused at once with :class:`ResultBusyError` (it spends
    no time); the same process may re-enter.  The lock file is removed on release.  On entry, an
    interrupted swap of ``dest`` is completed or rolled back (:func:`recover`).
    """
    dest = Path(dest)
    check_output_dir(dest)
    path = lock_path(dest)
    key = path.absolute()
    if key in _HELD:
        _HELD[key] += 1
        try:
            yield dest
        finally:
            _HELD[key] -= 1
        return
    import fcntl

    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise OutputError(f"cannot create the lock file: {exc.strerror or exc}", path=path) from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise ResultBusyError(f"another clothlab command is writing {dest} (lock {path.name} is held); "
                                  "wait for it to finish", path=dest) from None
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)  # the holder released and removed the file between our open and lock: try again
    _HELD[key] = 1
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        recover(dest)
        yield dest
    finally:
        del _HELD[key]
        try:
            path.unlink(missing_ok=True)
        finally:
            os.close(fd)


@contextlib.contextmanager
def prepare_result(dest, *, force: bool = False) -> Iterator[Path]:
    """Everything checked before work that will write result directory ``dest``: the output path can be
    written, no other process is writing it (the lock is held for the ``with`` block), an interrupted
    earlier run is recovered, and an existing result is refused without ``force``."""
    with result_lock(dest) as dest:
        if Path(dest).exists() and not force:
            _refuse_existing(Path(dest))
        yield Path(dest)


@contextlib.contextmanager
def atomic_directory(dest, *, force: bool = False) -> Iterator[Path]:
    """Build a result directory atomically: yield a fresh hidden temporary directory next to ``dest``.

    On a clean exit the temporary directory replaces ``dest``; on an exception it is removed and ``dest``
    is untouched.  If ``dest`` exists and ``force`` is false, :class:`ResultExistsError` is raised before
    any work is done.  The lock of ``dest`` is held throughout (:func:`result_lock`), so an interrupted
    earlier swap is recovered first and a concurrent writer is refused.

    The replacement is safe at every instant: where the file system can exchange two names atomically
    (Linux renameat2) the new directory and the old swap in one step and the old one is removed after;
    elsewhere the old one is renamed aside to ``.<name>.old-*`` first, and a kill between the two renames
    is undone by :func:`recover` on the next run.
    """
    dest = Path(dest)
    with result_lock(dest):
        if dest.exists() and not force:
            _refuse_existing(dest)
        parent = dest.parent
        tmp = Path(tempfile.mkdtemp(dir=parent, prefix=f".{dest.name}.tmp-"))
        try:
            yield tmp
            check_interrupted()  # never commit the result of a run the user interrupted
            os.chmod(tmp, 0o777 & ~_umask())
            _fsync_directory(tmp)
            _step("built")
            if dest.exists() or dest.is_symlink():
                if not force:  # appeared while we worked
                    _refuse_existing(dest)
                _replace(tmp, dest)
            else:
                os.rename(tmp, dest)
                _step("renamed")
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        _fsync_directory(parent)


def _replace(tmp: Path, dest: Path) -> None:
    """Put the complete directory ``tmp`` in the place of ``dest`` (see :func:`atomic_directory`)."""
    if _exchange(tmp, dest):
        _fsync_directory(dest.parent)
        _step("exchanged")
        _remove(tmp)  # now the old result
        return
    aside = dest.parent / f".{dest.name}.old-{uuid.uuid4().hex[:12]}"
    os.rename(dest, aside)
    _step("aside")
    try:
        os.rename(tmp, dest)
    except BaseException:
        os.rename(aside, dest)
        raise
    _step("renamed")
    _remove(aside)
