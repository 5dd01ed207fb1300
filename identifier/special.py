"""scipy's F-distribution survival function, callable from compiled (numba) code.

Compiled loops that make significance decisions (the identification wrapper decides a
flag per effect at every env step) call :data:`fdtrc` directly instead of returning to
Python for ``scipy.special.fdtrc``: the very same C routine, reached through scipy's
public Cython API (``scipy.special.cython_special``), so the numbers are identical.

A numba function that uses :data:`fdtrc` holds a raw address and cannot be cached on
disk (``cache=True``); it compiles once per process.
"""

from __future__ import annotations

import ctypes

from numba.extending import get_cython_function_address

__all__ = ["fdtrc"]

_SIGNATURE = ctypes.CFUNCTYPE(ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_int)


def _lookup() -> ctypes._CFuncPtr:
    # ``fdtrc`` is a fused (double/float) function in recent scipy: the double
    # specialisation is exported as ``__pyx_fuse_0fdtrc``; older releases export
    # ``fdtrc`` itself.  The last argument is Cython's ``skip_dispatch`` flag.
    for name in ("__pyx_fuse_0fdtrc", "fdtrc"):
        try:
            return _SIGNATURE(get_cython_function_address("scipy.special.cython_special", name))
        except ValueError:
            continue
    raise ImportError("scipy.special.cython_special exports no double-precision fdtrc; upgrade scipy")


#: ``fdtrc(d1, d2, F, 0)``: ``P(F_{d1,d2} > F)``, numba-callable (pass 0 as the last argument).
fdtrc = _lookup()
