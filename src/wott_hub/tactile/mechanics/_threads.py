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
from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import Any, ParamSpec, TypeVar

__all__ = ["single_threaded"]

_P = ParamSpec("_P")
_R = TypeVar("_R")

_controller: Any = None  # a threadpoolctl.ThreadpoolController (threadpoolctl ships no types)


def _limit() -> AbstractContextManager[object]:
    global _controller
    if _controller is None:  # created on first use, once NumPy's and SciPy's BLAS are loaded
        from threadpoolctl import ThreadpoolController

        _controller = ThreadpoolController()
    limiter: AbstractContextManager[object] = _controller.limit(limits=1, user_api="blas")
    return limiter


def single_threaded(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    @functools.wraps(fn)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with _limit():
            return fn(*args, **kwargs)

    return wrapper
