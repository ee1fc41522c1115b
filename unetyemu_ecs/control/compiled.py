"""How laws are compiled: numba, with the same options everywhere.

A law is written once. The hot path of a small fleet is dominated by the cost of calling NumPy on
arrays of a few elements (about a microsecond per operation), so a law that a per-step kernel calls is
compiled by numba from that one source:

- an arithmetic law without branches (``advance_pack``, ``terminal_from_ocv_v``) stays a NumPy
  function for array callers, and :func:`jit` compiles the same function for the scalars a kernel
  passes it;
- a law with branches per element (Glauert's inflow: Newton's method or bisection) is written for one
  rotor and compiled twice: :func:`jit` for kernels and :func:`ufunc` for arrays of any shape
  (broadcasting as NumPy does).

Compiled code is cached next to the source (``__pycache__``), so a process compiles a kernel only the
first time it ever runs it (about a second each). Division by zero gives ``inf``/``nan`` as in NumPy
(``error_model="numpy"``). A kernel keeps the interpreter lock: it runs for microseconds, and
releasing it would let a transport thread take it and make the simulation wait for it back.
"""

from __future__ import annotations

from typing import Any, Callable

import numba
import numpy as np
from numba.extending import overload

_OPTIONS = {"cache": True, "error_model": "numpy"}


def jit(fn: Callable) -> Callable:
    """``fn`` compiled by numba in nopython mode (lazily, per argument types; cached on disk)."""
    return numba.njit(**_OPTIONS)(fn)


def ufunc(signature: str) -> Callable[[Callable], Callable]:
    """Decorator: a scalar law compiled to a NumPy ufunc of ``signature`` (e.g. ``"f8(f8, f8)"``), eagerly."""
    def compile_ufunc(fn: Callable) -> Callable:
        return numba.vectorize([signature], cache=True)(fn)
    return compile_ufunc


def at(value: Any, k: int) -> Any:
    """A per-row parameter of row ``k``: ``value[k]`` of an (N,) array, or a scalar as it is (laws take gains of
    either kind; in compiled code the choice is made once per type, when the kernel is compiled)."""
    return value[k] if np.ndim(value) else value


@overload(at)
def _at_compiled(value, k):
    if isinstance(value, numba.types.Array):
        return lambda value, k: value[k]
    return lambda value, k: value


def gain_arg(value: float | np.ndarray) -> float | np.ndarray:
    """A gain or other per-row parameter as a kernel takes it (see :func:`at`): a float, or a contiguous float
    (N,) array."""
    if type(value) is np.ndarray and value.dtype == np.float64 and value.flags.c_contiguous:
        return value
    return np.ascontiguousarray(value, dtype=float) if np.ndim(value) else float(value)


def float_rows(values: Any, *tail: int) -> np.ndarray:
    """``values`` as a float array of shape (N, *tail): itself when it already is one (no call into NumPy)."""
    if type(values) is np.ndarray and values.dtype == np.float64 and values.shape[1:] == tail and values.ndim:
        return values
    return np.asarray(values, dtype=float).reshape(-1, *tail)


def rows_arg(*values: float | np.ndarray, n: int) -> list[np.ndarray]:
    """Per-row inputs (scalars or (n,) arrays) as the float (n,) arrays a kernel loops over."""
    return [v if type(v) is np.ndarray and v.dtype == np.float64 and v.shape == (n,)
            else np.broadcast_to(np.asarray(v, dtype=float).reshape(-1), (n,)) for v in values]


__all__ = ["at", "float_rows", "gain_arg", "jit", "rows_arg", "ufunc"]
