"""One BLAS thread for gnerun's linear algebra, unless the user chose otherwise.

gnerun factorises many small and medium dense systems (tens to a few hundred unknowns) in a row. A multithreaded
BLAS gains nothing on them and, on a machine whose cores are busy, stalls: a 12 ms solve took 1.7 s with
OpenBLAS's default threads while another process ran on the second of two cores. So gnerun asks for one thread:
the command line before numpy is loaded (through the environment), the library when it builds a solver (through
threadpoolctl, for a process that has loaded numpy already). A thread count the user set in the environment
(``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``) is left as it is.
"""

from __future__ import annotations

import os
import sys

_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
_done = False


def _chosen_by_user() -> bool:
    return any(v in os.environ for v in _VARIABLES)


def single_threaded_blas() -> None:
    """Ask for one BLAS thread (once per process), unless the user set a thread count."""
    global _done
    if _done or _chosen_by_user():
        _done = True
        return
    _done = True
    if "numpy" not in sys.modules:  # not loaded yet: the environment decides
        os.environ["OPENBLAS_NUM_THREADS"] = "1"
        return
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")
