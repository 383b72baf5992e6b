"""Compiler flags shared by every Numba kernel of refraster.

One place so that no kernel can quietly differ: no ``fastmath`` (a reference must be
bit-reproducible), ``cache=True`` (cold start: a second run compiles nothing).
``tests/test_config.py`` fails if a kernel hard-codes its own flags.
"""

JIT = dict(cache=True, nogil=True, fastmath=False)
#: Flags for kernels that run in parallel over independent output slices (tiles, rows).
PJIT = dict(cache=True, nogil=True, fastmath=False, parallel=True)
#: Small helpers called from inside kernels: inlined at Numba IR level, which lets LLVM keep
#: their values in registers (measured: the tile kernel runs 2.2× faster than with calls).
IJIT = dict(cache=True, nogil=True, fastmath=False, inline="always")
#: The quick tier of the render kernels (refraster/_tiers.py): the same source serial, its
#: helpers called, not inlined (a third of the compile; the same bytes, slower frames).
QJIT = dict(cache=True, nogil=True, fastmath=False)
#: The quick tier's helpers, only ever called from its kernels: no Python wrapper to compile.
QHJIT = dict(QJIT, no_cpython_wrapper=True, no_cfunc_wrapper=True)

# Numba's copy propagation, made faster while refraster's kernels compile (same results, same
# machine code; refraster/_compile_speed.py says what and why, and how to turn it off).
from refraster import _compile_speed  # noqa: E402

_compile_speed.install()
