"""Thread use of the numerical libraries in the core's hot loops."""
from __future__ import annotations

import contextlib
from typing import Iterator

from threadpoolctl import threadpool_limits


@contextlib.contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Run the enclosed code (or decorated function) with one BLAS thread.

    The workbench solves thousands of small least-squares problems (Gram matrices of
    ~10 000 × 15); OpenBLAS spreads each product over every core, and on a machine whose
    cores are busy its threads wait for each other: measured on a loaded 2-core machine,
    ``fit --auto`` of a 60 s run took 12–31 s with the default threads and 5.4 s with
    one.  Idle, one thread is as fast (the products are too small to split).
    """
    with threadpool_limits(limits=1, user_api='blas'):
        yield
