"""Set-up of the worker processes of the clusters clothlab starts (a Dask ``preload`` module).

A Ctrl-C in a terminal reaches every process of its group, the worker processes of a ``LocalCluster``
included.  The workers ignore it: the command itself stops (exit 130, one line, results kept or rolled back)
and shuts its cluster down, so no worker prints a traceback of its own.
"""

from __future__ import annotations


def dask_setup(worker) -> None:
    """Called by Dask in each worker process as it starts: ignore SIGINT there."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
