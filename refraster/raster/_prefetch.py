"""A software prefetch for kernels that gather rows by index (``llvm.prefetch``).

A pass over a dense mesh's face image meets a new face at nearly every pixel and waits on a
chain of loads: the face's row of ``faces``, then its vertices' rows. The out-of-order core
overlaps only the few pixels its window holds, so a kernel names the rows a pixel some
columns ahead will read; the loads then find them in cache. A prefetch is a hint: it reads
and writes nothing the kernel sees, cannot fault, and changes no output bit (the entry
digests say so). Numba has no prefetch of its own, hence this intrinsic (a call of LLVM's).
Numba's cache keys a kernel on its own file: after changing this one, clear the kernels'
caches (docs/performance.md, "How a frame is made fast").
"""

from __future__ import annotations

from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

__all__ = ["prefetch_row"]


@intrinsic
def prefetch_row(typingctx, arr, row):
    """Ask the cache for the first line of ``arr[row]`` (a C-ordered array, any integer row;
    an address outside the array is harmless: the hint never faults)."""
    if not isinstance(arr, types.Array) or not isinstance(row, types.Integer):
        return None
    sig = types.void(arr, row)

    def codegen(context, builder, signature, args):
        aty, rty = signature.args
        a, r = args
        r = context.cast(builder, r, rty, types.intp)
        ary = context.make_array(aty)(context, builder, a)
        stride = cgutils.unpack_tuple(builder, ary.strides, aty.ndim)[0]
        i64 = ir.IntType(64)
        addr = builder.add(builder.ptrtoint(ary.data, i64), builder.mul(r, stride))
        i8p = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [i8p, i32, i32, i32]),
            "llvm.prefetch.p0")
        # read (0), high locality (3: keep in every cache level), data (1)
        builder.call(fn, [builder.inttoptr(addr, i8p), ir.Constant(i32, 0),
                          ir.Constant(i32, 3), ir.Constant(i32, 1)])
        return context.get_dummy_value()

    return sig, codegen
