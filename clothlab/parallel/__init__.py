"""One execution layer for independent tasks: in-process (the default) or Dask distributed.

:func:`make_runner` gives a :class:`Runner`: :class:`InProcessRunner` (no Dask import), a Dask
``LocalCluster`` of ``workers`` processes with one thread each on loopback, or an existing cluster at
``scheduler`` (``tcp://HOST:PORT``, or the environment variable ``DASK_SCHEDULER_ADDRESS``).  A task is a plain
picklable function and its argument; :meth:`Runner.map` returns the results in submission order, retries a
failed task once and then returns a :class:`TaskFailure` for it (never drops it), and shows done / running /
failed counts through :mod:`clothlab.progress`.  Dask and distributed are the optional extra
``pip install "clothlab[dask]"`` (docs/parallel.md).
"""

from clothlab.parallel.runner import (
    DASK_EXTRA,
    SCHEDULER_ENV,
    InProcessRunner,
    Runner,
    Shared,
    TaskFailure,
    make_runner,
    raise_failures,
    require_dask,
)

__all__ = ["Runner", "InProcessRunner", "TaskFailure", "Shared", "make_runner", "raise_failures", "require_dask",
           "DASK_EXTRA", "SCHEDULER_ENV"]
