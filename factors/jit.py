"""The one way the factors compile a numeric kernel: the :func:`jit` decorator (numba).

Decided (issue 14): numba, a maintained compiler of numpy-style Python to machine code, for the
few kernels whose cost was numpy's per-call overhead on small arrays (the exact ellipse areas of
``quadloc.factors.overlap``, the iou / giou rows of ``quadloc.factors.metrics``, the level-set rows
of ``quadloc.factors.pose_level_set``, the camera frame and dual conics of
``quadloc.factors.pose_frame``): the kernels stay readable Python next to the
formulas they implement, no C toolchain is needed to install, and the wheels come from the package
registry. Why, costs and measurements: docs/design/factors.md, "Compiled kernels".

Lazy: importing a module with kernels neither imports numba nor sets a kernel up (a process
that never calls one, e.g. a CLI command on maps, starts ~0.4 s faster); the first call of any
kernel binds them all (:func:`_bind_all`), each then compiled at its first call, or loaded from
numba's on-disk cache.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable
from typing import Any, TypeVar, cast

#: numba options of every kernel: ``error_model="numpy"`` gives IEEE inf / nan on a division by
#: zero (as numpy) instead of an exception, which the kernels rely on where a derivative or a
#: direction vanishes; ``nogil``: a kernel releases the GIL while it runs.
NUMBA_OPTIONS: dict[str, Any] = {"error_model": "numpy", "nogil": True}

#: the declared kernels not yet bound: (function, the module global its dispatcher becomes)
_PENDING: list[tuple[Callable[..., Any], str]] = []
_LOCK = threading.Lock()
#: a kernel's type: the annotated Python function, whose signature its stand-in keeps
_Kernel = TypeVar("_Kernel", bound=Callable[..., Any])


def jit(fn: _Kernel) -> _Kernel:
    """Declare ``fn`` (a module-level function) a compiled kernel. Returns a stand-in under the
    same module name that binds every declared kernel at its first call; from then on the
    module's global IS the numba dispatcher (so kernels call each other compiled, and Python
    callers that look the name up reach numba directly). Typed as ``fn`` itself: callers are
    checked against the kernel's annotations."""
    return _declare(fn, fn.__name__)


def jit_for_kernels(fn: _Kernel, name: str) -> _Kernel:
    """Compile ``fn`` (a module-level function, numpy-style) for the OTHER kernels only: the
    compiled form becomes the module global ``name`` (which the kernels call, e.g. as
    ``module.name``), while Python callers keep calling ``fn`` itself, as numpy code. So one
    formula serves both without a compilation per array type at a Python call (a request
    would otherwise compile for every new array shape it passes). Returns the stand-in to
    assign to ``name``."""
    return _declare(fn, name)


def _declare(fn: _Kernel, name: str) -> _Kernel:
    """Declare ``fn`` compiled as its module's global ``name``; the stand-in binds every
    declared kernel at its first call."""
    _PENDING.append((fn, name))

    @functools.wraps(fn)
    def first_call(*args: Any) -> Any:
        _bind_all()
        return fn.__globals__[name](*args)

    return cast(_Kernel, first_call)  # wraps(fn): the same signature


def _bind_all() -> None:
    """Replace every declared kernel's module global by its numba dispatcher (once)."""
    with _LOCK:
        if not _PENDING:
            return
        for fn, name in _PENDING:
            fn.__globals__[name] = _dispatcher(fn)
        _PENDING.clear()


def _dispatcher(fn: Callable[..., Any]) -> Any:
    """``njit`` with :data:`NUMBA_OPTIONS` and numba's on-disk cache (``__pycache__`` next to
    the source, or ``NUMBA_CACHE_DIR``): a kernel compiles at its first call in a process that
    finds no cache entry (seconds), else loads in milliseconds. Where no cache directory is
    writable (a read-only file system) numba refuses to cache, and each process compiles
    (``quadloc.service.api.app`` compiles the kernels at start-up, before serving)."""
    from numba import njit  # here: importing the factors does not import numba

    try:
        return njit(cache=True, **NUMBA_OPTIONS)(fn)
    except RuntimeError:  # numba: "cannot cache function ...: no locator available"
        return njit(**NUMBA_OPTIONS)(fn)
