"""The :class:`Runner`: independent tasks in-process or on Dask distributed, in submission order, retried once.

A task is ``fn(item)`` (or ``fn(shared, item)`` when :meth:`Runner.map` is given ``shared``, an object sent to
every worker once) with ``fn`` a module-level function and ``item`` picklable.  On the worker an exception is
caught and returned as text (a clothlab error keeps its one-line message; no exception object has to survive
pickling); a task whose worker died fails with Dask's ``KilledWorker`` (the clusters started here allow no
silent re-run, so the retry is logged by name).  Either way the task is submitted once more (``retries``) and,
if it fails again, its slot in the results holds a :class:`TaskFailure` with the error: never dropped.
Results never depend on the backend or on the order tasks finish in; ``on_result(index, value)`` is called in
completion order, e.g. to write each result to a file as soon as it exists.
"""

from __future__ import annotations

import abc
import contextlib
import os
import traceback
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from clothlab.errors import ClothlabError
from clothlab.parallel.address import parse_scheduler_address, probe_scheduler
from clothlab.progress import Progress, get_logger

log = get_logger(__name__)

DASK_EXTRA = 'pip install "clothlab[dask]"'
"""How to install the optional Dask extra (named in the error when it is missing)."""
SCHEDULER_ENV = "DASK_SCHEDULER_ADDRESS"
"""Environment variable with the address of an existing Dask scheduler (used when no option is given)."""
CONNECT_TIMEOUT_S = 10.0
"""Seconds to wait for an existing scheduler before giving up (an error naming the address)."""
_NO_SHARED = object()


@dataclass(frozen=True)
class TaskFailure:
    """A task that failed on every attempt: its name, the last error (one line), attempts made, the
    worker-side traceback (empty for a lost worker)."""

    name: str
    error: str
    attempts: int
    traceback: str = ""

    def __str__(self) -> str:
        return f"{self.name}: {self.error}"


@dataclass(frozen=True)
class Shared:
    """An object placed on every worker once (:meth:`Runner.share`), for many :meth:`Runner.map` calls:
    ``value`` is what the tasks receive (the object, or Dask's handle to its copies), ``source`` the object
    itself (placed again if every worker holding a copy died)."""

    value: object
    source: object = None


@dataclass(frozen=True)
class _Raised:
    """What a task returned instead of a value when it raised (picklable: text only)."""

    error: str
    traceback: str


def _attempt(fn, item, *shared):
    """Run one task, ``fn(*shared, item)``, on a worker (or in-process); an exception comes back as
    :class:`_Raised`."""
    try:
        return fn(*shared, item)
    except Exception as exc:  # noqa: BLE001 - reported by name to the caller, never lost
        text = str(exc) if isinstance(exc, ClothlabError) else f"{type(exc).__name__}: {exc}"
        return _Raised(text, traceback.format_exc())


def raise_failures(results: Sequence, what: str) -> list:
    """``results`` unchanged if none is a :class:`TaskFailure`; otherwise a ClothlabError naming them."""
    failed = [r for r in results if isinstance(r, TaskFailure)]
    if failed:
        raise ClothlabError(f"{len(failed)} of {len(results)} {what} failed; first: {failed[0]}")
    return list(results)


class _Counts:
    """Progress of one :meth:`Runner.map`: done / running / failed counts in the stage's description."""

    def __init__(self, total: int, desc: str, slots: int, dashboard: str | None, enabled: bool | None = None):
        self.total, self.desc, self.slots, self.dashboard = total, desc, slots, dashboard
        self.done = self.failed = 0
        self.bar = Progress(total, self._text(), unit="task", enabled=enabled)

    def _text(self) -> str:
        running = min(self.slots, self.total - self.done - self.failed)
        link = f", dashboard {self.dashboard}" if self.dashboard else ""
        return f"{self.desc}: {self.done} done, {running} running, {self.failed} failed{link}"

    def finished(self, ok: bool) -> None:
        if ok:
            self.done += 1
        else:
            self.failed += 1
        self.bar.set_description(self._text())
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


class Runner(abc.ABC):
    """Where tasks run.  Subclasses provide ``_begin(fn, shared) -> handle``, ``_submit(handle, item) -> key``
    and ``_next(pending) -> (key, outcome)``."""

    workers: int = 1
    dashboard: str | None = None
    description: str = "in-process"

    def map(self, fn: Callable, items: Iterable, *, shared=_NO_SHARED, names: Sequence[str] | None = None,
            desc: str = "tasks", retries: int = 1, on_result: Callable[[int, object], None] | None = None,
            progress: bool = True) -> list:
        """``[fn(item) for item in items]`` (``fn(shared, item)`` with ``shared``, an object or a :class:`Shared`
        from :meth:`share`) in submission order; a task failing ``retries + 1`` times leaves a
        :class:`TaskFailure` in its slot (logged with its name).  ``progress`` False: no progress display."""
        items = list(items)
        names = list(names) if names is not None else [f"{desc} #{i + 1}" for i in range(len(items))]
        if len(names) != len(items):
            raise ValueError(f"{len(names)} names for {len(items)} tasks")
        results: list = [None] * len(items)
        if not items:
            return results
        counts = _Counts(len(items), desc, self.workers, self.dashboard, enabled=None if progress else False)
        pending = {}
        try:
            handle = self._begin(fn, shared)
            for i, item in enumerate(items):
                pending[self._submit(handle, item)] = (i, 1)
            while pending:
                key, outcome = self._next(pending)
                i, attempt = pending.pop(key)
                if isinstance(outcome, _Raised) and attempt <= retries:
                    log.warning("%s: task %s failed (%s); retrying it (attempt %d of %d)", desc, names[i],
                                outcome.error, attempt + 1, retries + 1)
                    pending[self._submit(handle, items[i])] = (i, attempt + 1)
                    continue
                if isinstance(outcome, _Raised):
                    outcome = TaskFailure(names[i], outcome.error, attempt, outcome.traceback)
                    log.warning("%s: task %s failed %d times, giving up: %s", desc, names[i], attempt,
                                outcome.error)
                results[i] = outcome
                counts.finished(not isinstance(outcome, TaskFailure))
                if on_result is not None:
                    on_result(i, outcome)
        except BaseException:
            self._cancel(list(pending))
            raise
        finally:
            counts.close()
        return results

    def share(self, value) -> Shared:
        """``value`` placed on the workers once, to pass as ``shared`` to many :meth:`map` calls."""
        return Shared(value)

    # backend hooks ------------------------------------------------------------------------------------
    @abc.abstractmethod
    def _begin(self, fn, shared):
        """Prepare ``fn`` (and ``shared``) for submission; returns what :meth:`_submit` takes."""

    @abc.abstractmethod
    def _submit(self, handle, item):
        """Start one task; returns its key in ``pending``."""

    @abc.abstractmethod
    def _next(self, pending: dict):
        """Wait for the next finished task of ``pending``: (key, outcome)."""

    def _cancel(self, keys: list) -> None:
        """Drop unfinished tasks (after an interrupt or an error in ``on_result``); default: nothing to drop."""
        return None

    def close(self) -> None:
        """Release the cluster (nothing for the in-process runner)."""
        return None

    def __enter__(self) -> Runner:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class InProcessRunner(Runner):
    """Tasks one after the other in this process (the default; imports no Dask)."""

    def _begin(self, fn, shared):
        self._queue: list = []
        self._count = 0
        if isinstance(shared, Shared):
            shared = shared.value
        return fn, () if shared is _NO_SHARED else (shared,)

    def _submit(self, handle, item):
        self._count += 1
        self._queue.append((self._count, handle, item))
        return self._count

    def _next(self, pending):
        key, (fn, shared), item = self._queue.pop(0)
        return key, _attempt(fn, item, *shared)

    def _cancel(self, keys):
        self._queue.clear()


def require_dask():
    """The ``distributed`` module, or a one-line ClothlabError naming the extra to install (call it before any
    work when a Dask runner will be needed)."""
    try:
        import distributed
    except ImportError:
        raise ClothlabError(f"running on several workers needs Dask, which is not installed; {DASK_EXTRA}",
                            field="--workers/--scheduler") from None
    return distributed


class DaskRunner(Runner):
    """Tasks on a Dask cluster: a ``LocalCluster`` of ``workers`` processes (one thread each, loopback) started
    here and shut down by :meth:`close`, or the existing scheduler at ``address``."""

    def __init__(self, *, workers: int | None = None, address=None):
        import logging

        distributed = require_dask()
        self.cluster = None
        self.client = None
        if isinstance(address, str):
            address = parse_scheduler_address(address, "--scheduler")
        self.address = None if address is None else address.text
        try:
            if address is None:
                self.cluster = distributed.LocalCluster(
                    n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1", protocol="tcp",
                    dashboard_address=":0", silence_logs=logging.ERROR,
                    scheduler_kwargs={"allowed_failures": 0},  # a lost worker fails its task: retried by name here
                    preload=["clothlab.parallel.worker"])  # workers ignore Ctrl-C: the command stops them
                self.client = _client(distributed, self.cluster)
                self.description = f"Dask LocalCluster, {workers} worker processes"
            else:
                probe_scheduler(address, CONNECT_TIMEOUT_S)  # bounded: a service that is not Dask is named
                try:
                    self.client = _client(distributed, address.text, timeout=CONNECT_TIMEOUT_S)
                except MemoryError:  # a reply announcing an absurd size: garbled, or not Dask's protocol
                    raise address.error(f"the service at {address.text} does not speak Dask's protocol (a reply "
                                        "announced an impossible size); check the host and port") from None
                except Exception as exc:  # noqa: BLE001 - a comms error, a garbled reply: one line naming it
                    text = " ".join(str(exc).split())[:200]
                    raise address.error(f"cannot reach the Dask scheduler at {address.text}: "
                                        f"{type(exc).__name__}: {text}") from None
                self.description = f"Dask cluster at {address.text}"
            info = self.client.scheduler_info()
        except BaseException:
            self.close()
            raise
        self.workers = max(1, sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values()))
        self.dashboard = self.client.dashboard_link if dashboard_enabled(self.client) else None
        log.info("%s (%d slots)%s", self.description, self.workers,
                 f", dashboard {self.dashboard}" if self.dashboard else "")

    def _begin(self, fn, shared):
        from distributed import as_completed

        self._done = as_completed([], with_results=False, loop=self.client.loop)
        if shared is _NO_SHARED:
            return [fn, None]
        return [fn, shared if isinstance(shared, Shared) else self.share(shared)]

    def share(self, value) -> Shared:
        [future] = self.client.scatter([value], broadcast=True, hash=False)  # a list: ``value`` as one object
        return Shared(future, source=value)

    def _submit(self, handle, item):
        fn, shared = handle
        args = ()
        if shared is not None:
            if shared.value.status != "finished":  # every copy was on workers that died: place it again
                log.info("shared data of the tasks lost with a worker; placing it on the workers again")
                shared = handle[1] = self.share(shared.source)
            args = (shared.value,)
        future = self.client.submit(_attempt, fn, item, *args, pure=False)
        self._done.add(future)
        return future

    def _next(self, pending):
        future = next(self._done)
        try:
            return future, future.result()
        except Exception as exc:  # noqa: BLE001 - KilledWorker (the worker died), a lost connection, ...
            return future, _Raised(f"{type(exc).__name__}: {exc}", "")

    def _cancel(self, keys):
        with contextlib.suppress(Exception):
            self.client.cancel(keys)

    def close(self) -> None:
        if self.client is not None:
            _close_client(self.client)
            self.client = None
        if self.cluster is not None:
            with contextlib.suppress(Exception):
                self.cluster.close(timeout=10)
            self.cluster = None


def _client(distributed, address, **kwargs):
    """A ``distributed.Client`` of ``address``, closed (and silenced: no ``Client.__del__`` traceback at exit)
    when making it fails.  The object is created before it connects so that a failed start can be closed."""
    client = distributed.Client.__new__(distributed.Client)
    try:
        client.__init__(address, set_as_default=False, **kwargs)
    except BaseException:
        _close_client(client)
        raise
    return client


def _close_client(client) -> None:
    """Close ``client`` within a few seconds; whatever happens, mark it closed so that its ``__del__`` does not
    try again (and print a traceback) at interpreter exit."""
    with contextlib.suppress(Exception):
        client.close(timeout=5)
    with contextlib.suppress(Exception):
        client.status = "closed"


def dashboard_enabled(client) -> bool:
    """True when the scheduler serves a dashboard page (the Bokeh dashboard: bokeh installed here)."""
    import importlib.util

    try:
        return "dashboard" in client.scheduler_info().get("services", {}) and \
            importlib.util.find_spec("bokeh") is not None
    except Exception:  # noqa: BLE001 - no dashboard then
        return False


def resolve_options(workers: int | None = None, scheduler: str | None = None, *, environ=None):
    """The checked choice of the options: ``(workers, address)`` with ``address`` a
    :class:`~clothlab.parallel.address.SchedulerAddress` (from ``scheduler``, else ``$DASK_SCHEDULER_ADDRESS``
    when ``workers`` is not given) or None.  Conflicting options and a malformed address are refused here,
    whether or not the command then distributes anything (one line naming the option or the variable)."""
    environ = os.environ if environ is None else environ
    if workers is not None and scheduler is not None:
        raise ClothlabError("give either --workers (a local cluster) or --scheduler (an existing one), not both",
                            field="--workers")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int) or workers < 1):
        raise ClothlabError(f"--workers needs at least 1 worker, got {workers}", field="--workers")
    if scheduler is not None:
        return workers, parse_scheduler_address(scheduler, "--scheduler")
    if workers is None and environ.get(SCHEDULER_ENV):
        return None, parse_scheduler_address(environ[SCHEDULER_ENV], SCHEDULER_ENV)
    return workers, None


def make_runner(workers: int | None = None, scheduler: str | None = None, *, environ=None) -> Runner:
    """The runner the options ask for: ``scheduler`` (an existing cluster), else ``workers`` (a LocalCluster of
    that many processes), else ``$DASK_SCHEDULER_ADDRESS``, else in-process (:func:`resolve_options`)."""
    workers, address = resolve_options(workers, scheduler, environ=environ)
    if address is not None:
        return DaskRunner(address=address)
    if workers is not None:
        return DaskRunner(workers=workers)
    return InProcessRunner()
