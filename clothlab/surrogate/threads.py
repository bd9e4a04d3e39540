"""One BLAS thread for the network's matrix products (threadpoolctl).

The surrogate's products are small (2 k-row chunks of width 64 in inference, batches of 4,096 in training):
a second OpenBLAS thread gains little on them and, on a loaded 2-core machine, spins.  Measured (this
machine kind, load 4-6): a render's 3,072 neural-lod queries took ~100 ms of shading CPU with the default
two threads against ~6 ms with one; an Adam step of batch 4,096 0.093 CPU-s against 0.025 (docs/notes/neural-log.md).
Hence every product of :mod:`clothlab.surrogate` runs inside :func:`one_blas_thread`, whatever the environment
(``OPENBLAS_NUM_THREADS`` is read only when numpy loads).  Entering the limit costs ~9 us.
"""

from __future__ import annotations

from threadpoolctl import ThreadpoolController

_controller: ThreadpoolController | None = None


def one_blas_thread():
    """Context manager: the BLAS libraries loaded in this process use one thread inside it."""
    global _controller
    if _controller is None:  # scans the loaded libraries once (~6 ms)
        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")
