"""Single-threaded BLAS around the contact solves.

Contact work is many small dense products and solves (tens to hundreds of
rows). On a loaded machine a multi-threaded OpenBLAS spends far longer
synchronising its threads than computing: a 121 x 121 solve took 5 ms with
two threads against 0.08 ms with one, measured on this project's 2-core box.
So these calls run with one BLAS thread, and the rest of the process keeps
whatever it had.
"""

from __future__ import annotations

import functools

__all__ = ["single_threaded"]

_controller = None


def _limit():
    global _controller
    if _controller is None:  # created on first use, once NumPy's and SciPy's BLAS are loaded
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    return _controller.limit(limits=1, user_api="blas")


def single_threaded(fn):
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with _limit():
            return fn(*args, **kwargs)

    return wrapper
