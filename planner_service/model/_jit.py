"""Optional compilation of the model's kernels with numba.

Every kernel is plain Python that numba can compile. When numba is missing, or when
``UAV_PLANNER_NO_NUMBA=1`` is set, the decorator returns the function unchanged: the
service still runs, slower. ``jit(f).py_func`` is always the uncompiled function, which
the pure-Python reference planner uses so that both run the same model.
"""

from __future__ import annotations

import os
from typing import Any, Callable, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

try:  # pragma: no cover - exercised by whichever environment runs the tests
    if os.environ.get("UAV_PLANNER_NO_NUMBA") == "1":
        raise ImportError("numba disabled by UAV_PLANNER_NO_NUMBA=1")
    import numba as _numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    _numba = None
    HAVE_NUMBA = False


def jit(func: F) -> F:
    """Compile ``func`` in nopython mode with an on-disk cache, or return it as is."""
    if _numba is None:
        func.py_func = func  # type: ignore[attr-defined]
        return func
    return _numba.njit(cache=True, nogil=True)(func)  # type: ignore[return-value]


def jit_borrow(func: F) -> F:
    """``jit`` for a kernel that only borrows arrays: it allocates none and returns none
    (numbers, or a record of numbers, at most), so it needs no reference counting.

    Numba counts a reference to every array it passes into a compiled function and out
    again, each member of a record of arrays included (its pass that drops needless counts
    does not apply to records), and each count is an atomic operation: about 10 ns here,
    which made a playout step several times slower. Compiled without numba's runtime
    (``_nrt=False``, the option numba's own benchmarks use) such a kernel counts nothing.
    Returning an array from it would corrupt the counts: never do that. If numba refuses the
    option, the kernel is compiled as ``jit`` does, the same results, slower.
    """
    return _borrowing(func)


def jit_inline(func: F) -> F:
    """``jit_borrow`` for a small kernel called in a loop with records of many arrays: it is
    compiled into each caller (numba passes a record member by member, tens of values a
    call, which costs more than the kernel's own work)."""
    return _borrowing(func, inline="always")


def _borrowing(func: F, **options: Any) -> F:
    if _numba is None:
        func.py_func = func  # type: ignore[attr-defined]
        return func
    try:
        return _numba.njit(cache=True, nogil=True, _nrt=False, **options)(func)  # type: ignore[return-value]
    except (KeyError, TypeError, ValueError):  # pragma: no cover - a numba without the option
        return _numba.njit(cache=True, nogil=True, **options)(func)  # type: ignore[return-value]


def py(func: Callable[..., Any]) -> Callable[..., Any]:
    """The uncompiled Python function behind a kernel."""
    return getattr(func, "py_func", func)
